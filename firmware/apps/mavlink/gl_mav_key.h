/**
 * @file gl_mav_key.h
 * @brief The host app's MAVLink signing key file: 64 hex digits (the 32-byte key), whitespace around allowed.
 *
 * The same format as `gainlink mavlink keygen` writes and `--signing-key FILE` of `gainlink mavlink upload`
 * / `params` reads (gainlink.mavlink.signing).
 */
#ifndef GL_MAV_KEY_H
#define GL_MAV_KEY_H

#include <stddef.h>
#include <stdint.h>

#include "gl_mav_platform.h" /* gl_mav_storage_t, GL_MAV_KEY_LEN */

/**
 * @brief Read a key file.
 * @param[in]  path     File.
 * @param[out] key      GL_MAV_KEY_LEN bytes.
 * @param[out] why      Reason of a failure (one line).
 * @param[in]  why_len  Size of `why`.
 * @return 0, or -1 (see `why`).
 */
int gl_mav_key_read(const char *path, uint8_t key[GL_MAV_KEY_LEN], char *why, size_t why_len);

/**
 * @brief Write a key file atomically (PATH.tmp with mode 0600, fsync, rename).
 * @param[in] path File.
 * @param[in] key  GL_MAV_KEY_LEN bytes.
 * @return 0, or -1.
 */
int gl_mav_key_write(const char *path, const uint8_t key[GL_MAV_KEY_LEN]);

/** @brief Signing timestamp of now: 10 us units since 2015-01-01 00:00 UTC (the MAVLink 2 epoch). @return It. */
uint64_t gl_mav_key_timestamp_now(void);

#endif /* GL_MAV_KEY_H */
