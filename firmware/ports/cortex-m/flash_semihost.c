/**
 * @file flash_semihost.c
 * @brief gl_mav_storage_t over semihosting files (see flash_semihost.h).
 */
#include "flash_semihost.h"

#include "semihost.h"

#define TMP_FILE "gl_flash.tmp"

static int flash_write(void *ctx, const uint8_t *data, size_t len)
{
    (void)ctx;
    int32_t fd = gl_sh_open(TMP_FILE, GL_SH_MODE_WB);
    if (fd < 0) {
        return -1;
    }
    int32_t rc = gl_sh_write_all(fd, data, len);
    gl_sh_close(fd);
    if (rc != 0 || gl_sh_rename(TMP_FILE, GL_FLASH_FILE) != 0) {
        (void)gl_sh_remove(TMP_FILE);
        return -1;
    }
    return 0;
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
