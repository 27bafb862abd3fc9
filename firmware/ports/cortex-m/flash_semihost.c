/**
 * @file flash_semihost.c
 * @brief gl_mav_storage_t over semihosting files (see flash_semihost.h).
 */
#include "flash_semihost.h"

#include "semihost.h"

#define TMP_FILE "gl_flash.tmp"

/** Write `len` bytes to TMP_FILE, then rename it over `name`. */
static int replace_file(const char *name, const uint8_t *data, size_t len)
{
    int32_t fd = gl_sh_open(TMP_FILE, GL_SH_MODE_WB);
    if (fd < 0) {
        return -1;
    }
    int32_t rc = gl_sh_write_all(fd, data, len);
    gl_sh_close(fd);
    if (rc != 0 || gl_sh_rename(TMP_FILE, name) != 0) {
        (void)gl_sh_remove(TMP_FILE);
        return -1;
    }
    return 0;
}

static int flash_write(void *ctx, const uint8_t *data, size_t len)
{
    (void)ctx;
    return replace_file(GL_FLASH_FILE, data, len);
}

int gl_flash_store_key(void *ctx, const uint8_t key[GL_MAV_KEY_LEN])
{
    (void)ctx;
    return replace_file(GL_FLASH_KEY_FILE, key, GL_MAV_KEY_LEN);
}

int gl_flash_load_key(uint8_t key[GL_MAV_KEY_LEN])
{
    int32_t fd = gl_sh_open(GL_FLASH_KEY_FILE, GL_SH_MODE_RB);
    if (fd < 0) {
        return 0;
    }
    int ok = gl_sh_flen(fd) == (int32_t)GL_MAV_KEY_LEN && gl_sh_read_all(fd, key, GL_MAV_KEY_LEN) == 0;
    gl_sh_close(fd);
    return ok;
}

int gl_flash_store_timestamp(uint64_t timestamp)
{
    uint8_t bytes[8];
    for (size_t i = 0; i < sizeof bytes; ++i) {
        bytes[i] = (uint8_t)(timestamp >> (8u * i));
    }
    return replace_file(GL_FLASH_TIMESTAMP_FILE, bytes, sizeof bytes);
}

uint64_t gl_flash_load_timestamp(void)
{
    int32_t fd = gl_sh_open(GL_FLASH_TIMESTAMP_FILE, GL_SH_MODE_RB);
    if (fd < 0) {
        return 0u;
    }
    uint8_t bytes[8];
    uint64_t timestamp = 0u;
    if (gl_sh_flen(fd) == (int32_t)sizeof bytes && gl_sh_read_all(fd, bytes, sizeof bytes) == 0) {
        for (size_t i = 0; i < sizeof bytes; ++i) {
            timestamp |= (uint64_t)bytes[i] << (8u * i);
        }
    }
    gl_sh_close(fd);
    return timestamp;
}

static long flash_read(void *ctx, uint8_t *data, size_t cap)
{
    (void)ctx;
    int32_t fd = gl_sh_open(GL_FLASH_FILE, GL_SH_MODE_RB);
    if (fd < 0) {
        return 0; /* never written: the compiled set runs */
    }
    int32_t size = gl_sh_flen(fd);
    long got = -1;
    if (size >= 0 && (size_t)size <= cap) {
        got = 0;
        while (got < size) {
            int32_t n = gl_sh_read_some(fd, &data[got], (size_t)(size - got));
            if (n <= 0) {
                got = -1;
                break;
            }
            got += n;
        }
    }
    gl_sh_close(fd);
    return got;
}

static const gl_mav_storage_t storage = {.ctx = 0, .write = flash_write, .read = flash_read};

const gl_mav_storage_t *gl_flash_storage(void)
{
    return &storage;
}
