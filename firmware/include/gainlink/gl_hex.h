/**
 * @file gl_hex.h
 * @brief Hexadecimal digits for the text protocols of the apps (slcan lines, the parameter store's lines, the
 *        image's option strings): one parser instead of one per protocol.
 */
#ifndef GL_HEX_H
#define GL_HEX_H

#include <stddef.h>
#include <stdint.h>

/** The value of one hex digit (either case), or -1 when `c` is not one. */
static inline int gl_hex_digit(char c)
{
    if (c >= '0' && c <= '9') {
        return c - '0';
    }
    if (c >= 'a' && c <= 'f') {
        return c - 'a' + 10;
    }
    if (c >= 'A' && c <= 'F') {
        return c - 'A' + 10;
    }
    return -1;
}

/**
 * Parse exactly `digits` (at most 16) hex digits at `text`, most significant first, into `*out`.
 * Returns 0, or -1 (and leaves `*out` alone) when one of them is not a hex digit or `digits` is out of range.
 */
static inline int gl_hex_parse(const char *text, size_t digits, uint64_t *out)
{
    if (digits == 0u || digits > 16u) {
        return -1;
    }
    uint64_t v = 0;
    for (size_t i = 0; i < digits; ++i) {
        int d = gl_hex_digit(text[i]);
        if (d < 0) {
            return -1;
        }
        v = (v << 4) | (uint64_t)d;
    }
    *out = v;
    return 0;
}

#endif /* GL_HEX_H */
