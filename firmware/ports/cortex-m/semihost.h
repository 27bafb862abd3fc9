/**
 * @file semihost.h
 * @brief ARM semihosting (bkpt 0xAB) for the Cortex-M port: file I/O with the host and a clean exit.
 */
#ifndef GAINLINK_SEMIHOST_H
#define GAINLINK_SEMIHOST_H

#include <stddef.h>
#include <stdint.h>

/** Exit statuses of the image (seen as QEMU's exit status). */
enum gl_exit {
    GL_EXIT_OK = 0,          /**< Done. */
    GL_EXIT_BAD_INPUT = 1,   /**< The input stream's header is malformed. */
    GL_EXIT_IO = 2,          /**< A semihosting read/write failed or came up short. */
    GL_EXIT_GAINS = 4,       /**< The built-in gain set was rejected by gl_law_init(). */
    GL_EXIT_FPU = 8,         /**< Startup self-test: FPU not enabled (GL_ERR_FPU). */
    GL_EXIT_FAULT = 9        /**< A HardFault / UsageFault / other fault occurred. */
};

/** Semihosting open modes (subset). */
#define GL_SH_MODE_RB 1
#define GL_SH_MODE_WB 5

/**
 * @brief Open a host file. @param[in] path NUL-terminated name. @param[in] mode GL_SH_MODE_*.
 * @return A handle >= 0, or -1.
 */
int32_t gl_sh_open(const char *path, uint32_t mode);

/**
 * @brief Read exactly `len` bytes (loops over short reads). @param[in] fd Handle. @param[out] buf Buffer.
 * @param[in] len Bytes. @return 0 on success, -1 on error or end of file.
 */
int32_t gl_sh_read_all(int32_t fd, void *buf, size_t len);

/**
 * @brief Write `len` bytes. @param[in] fd Handle. @param[in] buf Data. @param[in] len Bytes.
 * @return 0 on success, -1 otherwise.
 */
int32_t gl_sh_write_all(int32_t fd, const void *buf, size_t len);

/**
 * @brief Read at most `len` bytes. @param[in] fd Handle. @param[out] buf Buffer. @param[in] len Bytes.
 * @return Bytes read (0 at end of file), or -1.
 */
int32_t gl_sh_read_some(int32_t fd, void *buf, size_t len);

/** @brief Length of an open file. @param[in] fd Handle. @return Bytes, or -1. */
int32_t gl_sh_flen(int32_t fd);

/** @brief Delete a host file. @param[in] path Name. @return 0, or -1. */
int32_t gl_sh_remove(const char *path);

/** @brief Rename a host file (replacing `to`). @param[in] from Old name. @param[in] to New name. @return 0, or -1. */
int32_t gl_sh_rename(const char *from, const char *to);

/**
 * @brief The simulator's command line for the image (QEMU: `-semihosting-config ...,arg=A,arg=B` gives "A B";
 *        without arg= it is the kernel file name). NUL-terminated.
 * @param[out] buf Buffer. @param[in] len Its size. @return 0, or -1 (e.g. too long for `buf`).
 */
int32_t gl_sh_cmdline(char *buf, size_t len);

/**
 * @brief The simulator's command line split into words in place (spaces become NULs).
 * @param[out] buf Buffer for the line. @param[in] len Its size.
 * @param[out] words The words (the first: the program name). @param[in] max Room in `words`.
 * @return The number of words, or -1 when the line cannot be read.
 */
int gl_sh_cmdline_words(char *buf, size_t len, char *words[], int max);

/** @brief Close a handle. @param[in] fd Handle. */
void gl_sh_close(int32_t fd);

/** @brief Stop the simulator with `code` (SYS_EXIT_EXTENDED); never returns. @param[in] code Status. */
void gl_sh_exit(uint32_t code) __attribute__((noreturn));

#endif /* GAINLINK_SEMIHOST_H */
