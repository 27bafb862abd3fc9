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

#include "gl_mav_node.h"

/** Name of the stored set in QEMU's working directory. */
#define GL_FLASH_FILE "gl_flash.txt"

/** @brief The storage interface over the semihosting file. @return Static storage descriptor. */
const gl_mav_storage_t *gl_flash_storage(void);

#endif /* GAINLINK_FLASH_SEMIHOST_H */
