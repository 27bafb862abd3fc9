/**
 * @file gl_mav_file.c
 * @brief Storage file of the host MAVLink app: write to PATH.tmp, fsync, rename over PATH.
 */
#define _POSIX_C_SOURCE 200809L
#include "gl_mav_file.h"

#include <errno.h>
#include <stdio.h>
#include <unistd.h>

static int file_write(void *ctx, const uint8_t *data, size_t len)
{
    const gl_mav_file_t *file = ctx;
    char tmp[4096];
    if (snprintf(tmp, sizeof tmp, "%s.tmp", file->path) >= (int)sizeof tmp) {
        return -1;
    }
    FILE *f = fopen(tmp, "wb");
    if (f == NULL) {
        return -1;
    }
    int bad = fwrite(data, 1, len, f) != len;
    bad |= fflush(f) != 0;
    bad |= fsync(fileno(f)) != 0;
    bad |= fclose(f) != 0;
    if (bad || rename(tmp, file->path) != 0) {
        remove(tmp);
        return -1;
    }
    return 0;
}

static long file_read(void *ctx, uint8_t *data, size_t cap)
{
    const gl_mav_file_t *file = ctx;
    FILE *f = fopen(file->path, "rb");
    if (f == NULL) {
        return errno == ENOENT ? 0 : -1;
    }
    size_t n = fread(data, 1, cap, f);
    int more = fgetc(f) != EOF; /* longer than any set of this build: not ours */
    int bad = ferror(f);
    fclose(f);
    if (bad || more) {
        return -1;
    }
    return (long)n;
}

const gl_mav_storage_t *gl_mav_file_init(gl_mav_file_t *file, const char *path)
{
    file->path = path;
    file->storage.ctx = file;
    file->storage.write = file_write;
    file->storage.read = file_read;
    return &file->storage;
}
