/**
 * @file semihost.c
 * @brief ARM semihosting calls (bkpt 0xAB, operation in r0, argument block in r1).
 */
#include "semihost.h"

#include <string.h>

#define SYS_OPEN 0x01u
#define SYS_CLOSE 0x02u
#define SYS_WRITE 0x05u
#define SYS_READ 0x06u
#define SYS_FLEN 0x0Cu
#define SYS_REMOVE 0x0Eu
#define SYS_RENAME 0x0Fu
#define SYS_GET_CMDLINE 0x15u
#define SYS_EXIT_EXTENDED 0x20u
#define ADP_STOPPED_APPLICATION_EXIT 0x20026u

static int32_t semihost_call(uint32_t op, const void *arg)
{
    register uint32_t r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return (int32_t)r0;
}

int32_t gl_sh_open(const char *path, uint32_t mode)
{
    const uint32_t args[3] = {(uint32_t)(uintptr_t)path, mode, (uint32_t)strlen(path)};
    return semihost_call(SYS_OPEN, args);
}

int32_t gl_sh_read_all(int32_t fd, void *buf, size_t len)
{
    uint8_t *p = buf;
    while (len > 0u) {
        const uint32_t args[3] = {(uint32_t)fd, (uint32_t)(uintptr_t)p, (uint32_t)len};
        int32_t left = semihost_call(SYS_READ, args); /* bytes NOT read */
        if (left < 0 || (size_t)left > len) {
            return -1;
        }
        size_t got = len - (size_t)left;
        if (got == 0u) {
            return -1; /* end of file */
        }
        p += got;
        len -= got;
    }
    return 0;
}

int32_t gl_sh_write_all(int32_t fd, const void *buf, size_t len)
{
    const uint32_t args[3] = {(uint32_t)fd, (uint32_t)(uintptr_t)buf, (uint32_t)len};
    return semihost_call(SYS_WRITE, args) == 0 ? 0 : -1;
}

int32_t gl_sh_flen(int32_t fd)
{
    const uint32_t args[1] = {(uint32_t)fd};
    return semihost_call(SYS_FLEN, args);
}

int32_t gl_sh_read_some(int32_t fd, void *buf, size_t len)
{
    const uint32_t args[3] = {(uint32_t)fd, (uint32_t)(uintptr_t)buf, (uint32_t)len};
    int32_t left = semihost_call(SYS_READ, args);
    return (left < 0 || (size_t)left > len) ? -1 : (int32_t)(len - (size_t)left);
}

int32_t gl_sh_remove(const char *path)
{
    const uint32_t args[2] = {(uint32_t)(uintptr_t)path, (uint32_t)strlen(path)};
    return semihost_call(SYS_REMOVE, args) == 0 ? 0 : -1;
}

int32_t gl_sh_rename(const char *from, const char *to)
{
    const uint32_t args[4] = {(uint32_t)(uintptr_t)from, (uint32_t)strlen(from), (uint32_t)(uintptr_t)to,
                              (uint32_t)strlen(to)};
    return semihost_call(SYS_RENAME, args) == 0 ? 0 : -1;
}

int32_t gl_sh_cmdline(char *buf, size_t len)
{
    uint32_t args[2] = {(uint32_t)(uintptr_t)buf, (uint32_t)len};
    return semihost_call(SYS_GET_CMDLINE, args) == 0 ? 0 : -1;
}

int gl_sh_cmdline_words(char *buf, size_t len, char *words[], int max)
{
    if (gl_sh_cmdline(buf, len) != 0) {
        return -1;
    }
    int n = 0;
    char *at = buf;
    while (*at != '\0' && n < max) {
        while (*at == ' ') {
            *at++ = '\0';
        }
        if (*at == '\0') {
            break;
        }
        words[n++] = at;
        while (*at != '\0' && *at != ' ') {
            ++at;
        }
    }
    return n;
}

void gl_sh_close(int32_t fd)
{
    const uint32_t args[1] = {(uint32_t)fd};
    (void)semihost_call(SYS_CLOSE, args);
}

void gl_sh_exit(uint32_t code)
{
    const uint32_t args[2] = {ADP_STOPPED_APPLICATION_EXIT, code};
    for (;;) {
        (void)semihost_call(SYS_EXIT_EXTENDED, args);
    }
}
