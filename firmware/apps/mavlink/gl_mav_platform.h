/**
 * @file gl_mav_platform.h
 * @brief What the MAVLink node asks of a platform and nothing else: the storage interface and the signing key's
 *        length.
 *
 * No MAVLink and no law here: the storages (the host's gl_mav_file.c and key file gl_mav_key.c, the images'
 * flash_semihost.c) include this header alone, so they compile to the same objects for every artifact and the
 * compiler cache serves them (the node's own header pulls in all of mavgen's common.xml and the artifact's
 * structure).
 */
#ifndef GL_MAV_PLATFORM_H
#define GL_MAV_PLATFORM_H

#include <stddef.h>
#include <stdint.h>

/** Length of a signing key. */
#define GL_MAV_KEY_LEN 32u

/**
 * Persistent storage of the committed set: whole-blob read and atomic replace. A host supplies a file,
 * the QEMU image a semihosting file standing for flash, a board a flash sector (see firmware/README.md).
 */
typedef struct gl_mav_storage {
    void *ctx; /**< Passed back to both functions. */
    /** Replace the stored bytes atomically (an interrupted write keeps the old ones); 0 ok, -1 failed. */
    int (*write)(void *ctx, const uint8_t *data, size_t len);
    /** Read the stored bytes into `data` (at most `cap`); bytes read, 0 when nothing is stored, -1 on error. */
    long (*read)(void *ctx, uint8_t *data, size_t cap);
} gl_mav_storage_t;

#endif /* GL_MAV_PLATFORM_H */
