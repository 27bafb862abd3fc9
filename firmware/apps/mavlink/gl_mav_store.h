/**
 * @file gl_mav_store.h
 * @brief The committed gain set as persistent bytes: encode for storage, decode and check on load.
 *
 * Format (ASCII text, one line per item, LF endings): an optional `#` comment line, then one
 * `ID BITS` line per gain parameter of the committed set, where BITS is the float's IEEE-754
 * binary32 pattern (an integer law's table: the int32's bits) as exactly 8 lowercase hex digits (exact, and needs no
 * printf/strtof on a microcontroller), and a last line `GL_HASH BITS` with the set's CRC-32. Loading rebuilds a whole
 * gain set from the bytes and accepts it only if it passes the law's checks (gl_law_stage(): signature or
 * dimensions, CRC, finiteness, limits, derivation); on any error nothing changes.
 *
 * Where the bytes live is the caller's business (gl_mav_storage_t in gl_mav_node.h): a file on the
 * host, a semihosting file standing for flash under QEMU, a flash sector on a board.
 */
#ifndef GL_MAV_STORE_H
#define GL_MAV_STORE_H

#include <stddef.h>
#include <stdint.h>

#include "gl_mav_params.h"

/** Longest line: a 16-character id, a space, 8 hex digits, LF. */
#define GL_MAV_STORE_LINE 26u

/** Bytes needed to encode any committed set of this build (comment line included). */
#define GL_MAV_STORE_MAX (64u + GL_MAV_STORE_LINE * (uint32_t)GL_MAV_MAX_PARAMS)

/** Why stored bytes were refused. */
typedef enum gl_mav_store_error {
    GL_MAV_STORE_OK = 0,        /**< Accepted. */
    GL_MAV_STORE_E_SYNTAX = 1,  /**< A line is not `ID BITS` (see the line number). */
    GL_MAV_STORE_E_UNKNOWN = 2, /**< An id that is not a gain parameter of this build. */
    GL_MAV_STORE_E_NUMBER = 3,  /**< BITS is not 8 hex digits. */
    GL_MAV_STORE_E_NO_HASH = 4, /**< No `GL_HASH` line. */
    GL_MAV_STORE_E_REFUSED = 5, /**< The set failed the law's checks (see the status). */
    GL_MAV_STORE_E_RANGE = 6,   /**< An integer beyond its parameter's word (see the line number). */
} gl_mav_store_error_t;

/** Outcome of a decode: the error, the 1-based line it is on, and the loop's status for a refusal. */
typedef struct gl_mav_store_result {
    gl_mav_store_error_t error; /**< GL_MAV_STORE_OK or why not. */
    uint32_t line;              /**< Offending line (0 when not about a line). */
    int32_t status;             /**< gl_status_t of a GL_MAV_STORE_E_REFUSED set. */
} gl_mav_store_result_t;

/**
 * @brief Encode the committed set.
 * @param[in]  table  Parameter table.
 * @param[out] buf    Output bytes.
 * @param[in]  cap    Size of `buf` (GL_MAV_STORE_MAX always suffices).
 * @return Bytes written, or 0 when `cap` is too small.
 */
size_t gl_mav_store_encode(const gl_mav_params_t *table, uint8_t *buf, size_t cap);

/**
 * @brief Decode stored bytes and make them the committed (and staged) set.
 * @param[in,out] table  Parameter table (unchanged unless the result is GL_MAV_STORE_OK).
 * @param[in]     buf    Stored bytes.
 * @param[in]     len    Their length.
 * @return The outcome.
 */
gl_mav_store_result_t gl_mav_store_decode(gl_mav_params_t *table, const uint8_t *buf, size_t len);

/**
 * @brief The error in words (static string).
 * @param[in] error Error.
 * @return Its description.
 */
const char *gl_mav_store_strerror(gl_mav_store_error_t error);

#endif /* GL_MAV_STORE_H */
