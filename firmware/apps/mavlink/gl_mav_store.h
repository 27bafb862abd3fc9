/**
 * @file gl_mav_store.h
 * @brief Persistent parameter storage of the host MAVLink app: a text file, written atomically.
 *
 * Format: a comment line, then one `ID VALUE` line per REAL32 parameter of the committed set
 * (`%.9g`, round-trip for float32) and a last line `GL_HASH <crc32 as unsigned decimal>`. Loading
 * rebuilds a whole gain set from the file and accepts it only if it passes the library's checks
 * (dimensions, CRC, finiteness, limits).
 */
#ifndef GL_MAV_STORE_H
#define GL_MAV_STORE_H

#include <stddef.h>

#include "gl_mav_params.h"

/**
 * @brief Write the committed set to `path` (temporary file, fsync, rename).
 * @param[in] table  Parameter table.
 * @param[in] path   File path.
 * @return 0 on success, -1 on an I/O error.
 */
int gl_mav_store_save(const gl_mav_params_t *table, const char *path);

/**
 * @brief Load `path` and make it the committed (and staged) set.
 * @param[in,out] table   Parameter table (unchanged on failure).
 * @param[in]     path    File path.
 * @param[out]    why     Reason of a failure, NUL-terminated.
 * @param[in]     why_len Size of `why`.
 * @return 0 loaded, 1 no such file, -1 malformed or refused (see `why`).
 */
int gl_mav_store_load(gl_mav_params_t *table, const char *path, char *why, size_t why_len);

#endif /* GL_MAV_STORE_H */
