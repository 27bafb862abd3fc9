/**
 * @file gl_fmaf_check.c
 * @brief Host check of gl_fmaf() against the C library's fmaf() (IEEE fusedMultiplyAdd), bit for bit.
 *
 * Usage: gl_fmaf_check COUNT SEED [gl|double]
 * Draws COUNT triples from each class below (xorshift, seeded), compares the bits of the implementation
 * under test with fmaf() and prints `cases=N mismatches=M` (and the first few mismatches). Exit 0 when
 * every result matches. `double` checks newlib's formula (float)((double)a * b + c) instead, which rounds
 * twice: it must mismatch on the tie classes (the check is able to fail).
 *
 * Classes: raw bit patterns (NaN, infinities, zeros included); cancellation (c close to -a*b); ties
 * (short significands, so the exact sum often falls on a rounding midpoint); results near and below the
 * smallest normal; products near overflow; double-rounding traps (a product on a float midpoint plus an
 * addend below double's ulp); addends far below or above the product (sticky bits).
 * Build: cc -O2 -ffp-contract=off -I firmware/src firmware/src/gl_fmaf.c gl_fmaf_check.c -lm
 */
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gl_fmaf.h"

static uint64_t rng_state;

static uint32_t rnd32(void)
{
    uint64_t x = rng_state;
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    rng_state = x;
    return (uint32_t)(x >> 16);
}

static float from_bits(uint32_t b)
{
    float f;
    memcpy(&f, &b, sizeof f);
    return f;
}

static uint32_t to_bits(float f)
{
    uint32_t b;
    memcpy(&b, &f, sizeof b);
    return b;
}

/** A float with a random sign, biased exponent in [lo, hi] and random fraction. */
static float rnd_float(uint32_t lo, uint32_t hi)
{
    uint32_t e = lo + rnd32() % (hi - lo + 1u);
    return from_bits((rnd32() & 0x80000000u) | (e << 23) | (rnd32() & 0x007FFFFFu));
}

/** A float whose significand has only `bits` significant bits (ties become likely). */
static float rnd_short(int bits, int exp_lo, int exp_hi)
{
    int32_t m = (int32_t)(rnd32() & ((1u << bits) - 1u)) | 1;
    int e = exp_lo + (int)(rnd32() % (uint32_t)(exp_hi - exp_lo + 1));
    float v = ldexpf((float)m, e);
    return (rnd32() & 1u) ? -v : v;
}

typedef struct {
    float a, b, c;
} triple_t;

static triple_t draw(int cls)
{
    triple_t t;
    switch (cls) {
    case 0: /* raw bits */
        t.a = from_bits(rnd32());
        t.b = from_bits(rnd32());
        t.c = from_bits(rnd32());
        break;
    case 1: /* cancellation: c within a few ulps of -a*b */
        t.a = rnd_float(100, 154);
        t.b = rnd_float(100, 154);
        t.c = -(t.a * t.b);
        t.c = from_bits(to_bits(t.c) + (rnd32() % 7u) - 3u);
        break;
    case 2: /* ties: short significands, nearby exponents */
        t.a = rnd_short(13, -8, 8);
        t.b = rnd_short(13, -8, 8);
        t.c = rnd_short(24, -10, 20);
        break;
    case 3: /* around the smallest normal: subnormal results and operands */
        t.a = rnd_float(0, 80);
        t.b = rnd_float(60, 127);
        t.c = rnd_float(0, 3);
        break;
    case 4: /* near overflow */
        t.a = rnd_float(190, 254);
        t.b = rnd_float(127, 192);
        t.c = rnd_float(200, 254);
        break;
    case 5: /* double-rounding traps: a 25-bit product (a float midpoint) plus an addend below double's ulp */
        t.a = rnd_short(13, -6, 6);
        t.b = ldexpf(rnd_short(12, 0, 0), 12);
        t.c = ldexpf(rnd_short(24, -2, 2), -60);
        break;
    default: /* addend far from the product (sticky bits, both orders) */
        t.a = rnd_float(60, 190);
        t.b = rnd_float(60, 190);
        t.c = (rnd32() & 1u) ? rnd_float(1, 80) : rnd_float(170, 254);
        break;
    }
    return t;
}

static float double_rounded(float a, float b, float c)
{
    return (float)((double)a * (double)b + (double)c);
}

static int same(float x, float y)
{
    return (isnan(x) && isnan(y)) || to_bits(x) == to_bits(y);
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: %s COUNT SEED [gl|double]\n", argv[0]);
        return 2;
    }
    const uint64_t count = strtoull(argv[1], NULL, 0);
    rng_state = strtoull(argv[2], NULL, 0) * 0x9E3779B97F4A7C15ull + 1u;
    const int use_double = argc > 3 && strcmp(argv[3], "double") == 0;
    uint64_t cases = 0, bad = 0;
    for (int cls = 0; cls < 7; ++cls) {
        for (uint64_t i = 0; i < count; ++i) {
            triple_t t = draw(cls);
            float want = fmaf(t.a, t.b, t.c);
            float got = use_double ? double_rounded(t.a, t.b, t.c) : gl_fmaf(t.a, t.b, t.c);
            ++cases;
            if (!same(want, got)) {
                if (bad < 5) {
                    printf("class %d: fma(%a, %a, %a) = %a, got %a\n", cls, (double)t.a, (double)t.b, (double)t.c,
                           (double)want, (double)got);
                }
                ++bad;
            }
        }
    }
    printf("cases=%" PRIu64 " mismatches=%" PRIu64 "\n", cases, bad);
    return bad == 0 ? 0 : 1;
}
