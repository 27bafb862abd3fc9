/**
 * @file gl_mav_key.c
 * @brief Signing key file of the host MAVLink app (see gl_mav_key.h).
 */
#define _POSIX_C_SOURCE 200809L
#include "gl_mav_key.h"

#include <ctype.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

/** 2015-01-01 00:00:00 UTC in Unix seconds. */
#define MAVLINK_EPOCH_S 1420070400ull

static int hex_value(int c)
{
    if (c >= '0' && c <= '9') {
        return c - '0';
    }
    c = tolower(c);
    return (c >= 'a' && c <= 'f') ? c - 'a' + 10 : -1;
}

int gl_mav_key_read(const char *path, uint8_t key[GL_MAV_KEY_LEN], char *why, size_t why_len)
{
    FILE *f = fopen(path, "rb");
    if (f == NULL) {
        snprintf(why, why_len, "%s", strerror(errno));
        return -1;
    }
    char text[256];
    size_t n = fread(text, 1, sizeof text, f);
    fclose(f);
    size_t at = 0, digits = 0;
    while (at < n && isspace((unsigned char)text[at])) {
        ++at;
    }
    for (; at < n && digits < 2u * GL_MAV_KEY_LEN && hex_value(text[at]) >= 0; ++at, ++digits) {
        int v = hex_value(text[at]);
        key[digits / 2u] = (uint8_t)((digits % 2u) ? (key[digits / 2u] | v) : (v << 4));
    }
    while (at < n && isspace((unsigned char)text[at])) {
        ++at;
    }
    if (digits != 2u * GL_MAV_KEY_LEN || at != n) {
        snprintf(why, why_len, "expected exactly %u hex digits (a 32-byte key, as `gainlink mavlink keygen` writes)",
                 2u * GL_MAV_KEY_LEN);
        return -1;
    }
    return 0;
}

int gl_mav_key_write(const char *path, const uint8_t key[GL_MAV_KEY_LEN])
{
    char tmp[4096];
    if (snprintf(tmp, sizeof tmp, "%s.tmp", path) >= (int)sizeof tmp) {
        return -1;
    }
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC, 0600);
    if (fd < 0) {
        return -1;
    }
    char text[2u * GL_MAV_KEY_LEN + 1u];
    for (size_t i = 0; i < GL_MAV_KEY_LEN; ++i) {
        snprintf(&text[2u * i], 3, "%02x", key[i]);
    }
    text[2u * GL_MAV_KEY_LEN] = '\n';
    int bad = write(fd, text, sizeof text) != (ssize_t)sizeof text;
    bad |= fsync(fd) != 0;
    bad |= close(fd) != 0;
    if (bad || rename(tmp, path) != 0) {
        unlink(tmp);
        return -1;
    }
    return 0;
}

uint64_t gl_mav_key_timestamp_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    if ((uint64_t)ts.tv_sec < MAVLINK_EPOCH_S) {
        return 0u;
    }
    return ((uint64_t)ts.tv_sec - MAVLINK_EPOCH_S) * 100000u + (uint64_t)ts.tv_nsec / 10000u;
}
