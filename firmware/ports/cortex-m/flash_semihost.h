/**
 * @file flash_semihost.h
 * @brief Parameter storage of the image under QEMU: a semihosting file standing for a flash sector.
 *
 * The committed set is written to `gl_flash.tmp` in QEMU's working directory, which is then renamed
 * over `gl_flash.txt` (a crash mid-write leaves the old set, as an A/B sector pair would); it is read
 * back from `gl_flash.txt` at start. A board port supplies the same two functions over its flash
 * (see firmware/README.md: erase and program a reserved sector, keep two copies or a sequence number).
 */
#ifndef GAINLINK_FLASH_SEMIHOST_H
#define GAINLINK_FLASH_SEMIHOST_H

#include "gl_mav_platform.h" /* gl_mav_storage_t, GL_MAV_KEY_LEN */

/** Name of the stored set in QEMU's working directory. */
#define GL_FLASH_FILE "gl_flash.txt"

/** Name of the MAVLink signing key (32 raw bytes) in QEMU's working directory. */
#define GL_FLASH_KEY_FILE "gl_key.bin"

/** Name of the newest accepted MAVLink signing timestamp (8 bytes, little-endian) in QEMU's working directory. */
#define GL_FLASH_TIMESTAMP_FILE "gl_sign_ts.bin"

/** @brief The storage interface over the semihosting file. @return Static storage descriptor. */
const gl_mav_storage_t *gl_flash_storage(void);

/**
 * @brief Keep a signing key (set by SETUP_SIGNING) for the next start: ::gl_mav_port_t::store_key.
 * @param[in] ctx Unused. @param[in] key GL_MAV_KEY_LEN bytes. @return 0 kept, -1 failed.
 */
int gl_flash_store_key(void *ctx, const uint8_t key[GL_MAV_KEY_LEN]);

/**
 * @brief The kept signing key.
 * @param[out] key GL_MAV_KEY_LEN bytes.
 * @return 1 when a key was kept, 0 when none.
 */
int gl_flash_load_key(uint8_t key[GL_MAV_KEY_LEN]);

/**
 * @brief Keep the signing timestamp for the next start (a board without a wall clock restarts from it).
 * @param[in] timestamp 10 us units since 2015-01-01 UTC. @return 0 kept, -1 failed.
 */
int gl_flash_store_timestamp(uint64_t timestamp);

/** @brief The kept signing timestamp. @return It, or 0 when none was kept. */
uint64_t gl_flash_load_timestamp(void);

#endif /* GAINLINK_FLASH_SEMIHOST_H */
