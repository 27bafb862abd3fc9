/**
 * @file gl_crc32.h
 * @brief CRC-32 (zlib's polynomial 0xEDB88320, bitwise, no table) for the gain sets' hashes: one definition for
 *        every law (gl_gains_check.c, gl_fixed.c, gl_sched.c, gl_mpc.c), the same as Python's zlib.crc32.
 *
 * The register is passed and returned as it runs (start with 0xFFFFFFFF, invert at the end); a word is taken as
 * its four little-endian bytes whatever the host's byte order.
 */
#ifndef GL_CRC32_H
#define GL_CRC32_H

#include <stddef.h>
#include <stdint.h>

/** The register after one more byte. */
static inline uint32_t gl_crc32_byte(uint32_t c, uint32_t byte)
{
    c ^= byte & 0xFFu;
    for (unsigned i = 0; i < 8u; ++i) {
        c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
    }
    return c;
}

/** The register after a 32-bit word's four little-endian bytes. */
static inline uint32_t gl_crc32_word(uint32_t c, uint32_t word)
{
    for (unsigned b = 0; b < 4u; ++b) {
        c = gl_crc32_byte(c, word >> (8u * b));
    }
    return c;
}

/** The CRC-32 of `size` bytes at `data` as they lie in memory (started and inverted here). */
static inline uint32_t gl_crc32_bytes(const void *data, size_t size)
{
    const uint8_t *b = (const uint8_t *)data;
    uint32_t c = 0xFFFFFFFFu;
    for (size_t k = 0; k < size; ++k) {
        c = gl_crc32_byte(c, b[k]);
    }
    return ~c;
}

#endif /* GL_CRC32_H */
