/**
 * @file gl_fmaf.c
 * @brief Correctly rounded single-precision fused multiply-add in integer arithmetic, for cores without an FPU.
 *
 * newlib's `fmaf` computes `(float)((double)a * b + c)`: the product is exact in double, but the sum is
 * rounded twice (to double, then to float) and can land one ulp away from the IEEE result. Hardware
 * `vfma.f32` and the host's libm round once, so a soft-float build that used newlib's would not equal the
 * host bit for bit. gl_fmaf() rounds once, to nearest with ties to even, exactly as IEEE 754 fusedMultiplyAdd:
 *
 * - the 24 x 24-bit significand product is exact in 48 bits;
 * - product and addend are both normalised with their leading one at bit 61 of a 64-bit word, the smaller
 *   shifted right to the larger's exponent with every lost bit ORed into bit 0 (sticky), then added or
 *   subtracted; at least 60 significant bits remain above the sticky bit, so one rounding of that sum to
 *   24 bits (or to the subnormal grid) is the rounding of the exact value;
 * - zeros, infinities and NaNs go through the FPU-less float operations, whose results are exact there.
 *
 * Normal operands (the usual case) take constant shifts instead of leading-zero counts, and a normal
 * result is rounded in the upper 32-bit word; ARMv6-M forms the product from 16-bit halves (it has no
 * 32 x 32 -> 64 multiply, and GCC would call the general 64 x 64 one). GL_FMAF_SPLIT_MULTIPLY selects that
 * form on any compiler, so the host check (firmware/tools/gl_fmaf_check.c) covers it too.
 * Only round-to-nearest is implemented (the only mode the library uses); no exception flags are raised.
 */
#include <stdint.h>
#include <string.h>

#include "gl_fmaf.h"

#define GL_F32_SIGN 0x80000000u
#define GL_F32_EXP_MASK 0xFFu
#define GL_F32_FRAC_MASK 0x007FFFFFu
#define GL_F32_HIDDEN 0x00800000u
#define GL_F32_INF 0x7F800000u
#define GL_TOP_BIT 61

/** A finite non-zero value as sign, integer significand and power of two: (-1)^neg * sig * 2^exp. */
typedef struct {
    uint32_t neg;
    int32_t exp;
    uint64_t sig;
} gl_unpacked_t;

static uint32_t f32_bits(float x)
{
    uint32_t b;
    memcpy(&b, &x, sizeof b);
    return b;
}

static float f32_from_bits(uint32_t b)
{
    float x;
    memcpy(&x, &b, sizeof x);
    return x;
}

/** Leading-zero count of a non-zero 64-bit word, in 32-bit halves (ARMv6-M has no CLZ instruction). */
static int clz64(uint64_t v)
{
    uint32_t hi = (uint32_t)(v >> 32);
    return hi != 0u ? __builtin_clz(hi) : 32 + __builtin_clz((uint32_t)v);
}

/** Index of the leading one of a non-zero word; after an addition it is usually 60, 61 or 62. */
static int32_t lead_index(uint64_t v)
{
    const uint32_t hi = (uint32_t)(v >> 32);
    if ((hi >> 30) != 0u) {
        return (hi >> 31) != 0u ? 63 : 62;
    }
    if ((hi >> 28) != 0u) {
        return (hi >> 29) != 0u ? 61 : 60;
    }
    return 63 - clz64(v);
}

/** The exact 48-bit product of two 24-bit significands. */
static uint64_t mul24(uint32_t a, uint32_t b)
{
#if defined(__ARM_ARCH_6M__) || defined(GL_FMAF_SPLIT_MULTIPLY)
    const uint32_t al = a & 0xFFFFu, ah = a >> 16, bl = b & 0xFFFFu, bh = b >> 16;
    const uint32_t lo = al * bl;
    const uint32_t mid = al * bh + ah * bl; /* < 2^25: ah, bh < 2^8 */
    const uint32_t low = lo + (mid << 16);
    const uint32_t high = ah * bh + (mid >> 16) + (low < lo ? 1u : 0u);
    return ((uint64_t)high << 32) | low;
#else
    return (uint64_t)a * b;
#endif
}

/** Shift the significand so that its leading one sits at bit GL_TOP_BIT (exactly, no bits are lost). */
static void normalise(gl_unpacked_t *u)
{
    int shift = clz64(u->sig) - (63 - GL_TOP_BIT);
    u->sig <<= shift;
    u->exp -= shift;
}

/** Unpack the bits of a finite, non-zero float. */
static gl_unpacked_t unpack(uint32_t b)
{
    gl_unpacked_t u;
    uint32_t e = (b >> 23) & GL_F32_EXP_MASK;
    u.neg = b >> 31;
    u.sig = b & GL_F32_FRAC_MASK;
    if (e != 0u) {
        u.sig |= GL_F32_HIDDEN;
        u.exp = (int32_t)e - 150;
    } else {
        u.exp = -149; /* subnormal */
    }
    return u;
}

/** The product a * b of finite, non-zero floats, exact and normalised (leading one at GL_TOP_BIT). */
static gl_unpacked_t product(uint32_t ab, uint32_t bb)
{
    const uint32_t ea = (ab >> 23) & GL_F32_EXP_MASK;
    const uint32_t eb = (bb >> 23) & GL_F32_EXP_MASK;
    gl_unpacked_t p;
    p.neg = (ab ^ bb) >> 31;
    if (ea != 0u && eb != 0u) { /* normal: the product of two 24-bit significands is in [2^46, 2^48) */
        p.sig = mul24((ab & GL_F32_FRAC_MASK) | GL_F32_HIDDEN, (bb & GL_F32_FRAC_MASK) | GL_F32_HIDDEN);
        const int32_t shift = (p.sig >> 47) != 0u ? GL_TOP_BIT - 47 : GL_TOP_BIT - 46;
        p.sig <<= shift;
        p.exp = (int32_t)(ea + eb) - 300 - shift;
        return p;
    }
    gl_unpacked_t a = unpack(ab);
    gl_unpacked_t b = unpack(bb);
    p.sig = mul24((uint32_t)a.sig, (uint32_t)b.sig);
    p.exp = a.exp + b.exp;
    normalise(&p);
    return p;
}

/** A finite, non-zero addend, normalised (leading one at GL_TOP_BIT). */
static gl_unpacked_t addend(uint32_t cb)
{
    gl_unpacked_t c = unpack(cb);
    if (((cb >> 23) & GL_F32_EXP_MASK) != 0u) {
        c.sig <<= GL_TOP_BIT - 23;
        c.exp -= GL_TOP_BIT - 23;
    } else {
        normalise(&c);
    }
    return c;
}

/** Shift right by `d` >= 0 bits, ORing everything shifted out into bit 0. */
static uint64_t shift_right_sticky(uint64_t v, int32_t d)
{
    if (d == 0) {
        return v;
    }
    if (d > 62) {
        return v != 0u ? 1u : 0u;
    }
    uint64_t lost = v & ((UINT64_C(1) << d) - 1u);
    return (v >> d) | (lost != 0u ? 1u : 0u);
}

/** Shift right by `d` >= 1 bits, rounding to nearest with ties to even. */
static uint64_t shift_right_round(uint64_t v, int32_t d)
{
    if (d > 32 && d < 64) { /* a normal result (d = 37 to 39): the upper word, and whether the lower is 0 */
        const uint32_t hi = (uint32_t)(v >> 32);
        const uint32_t lo = (uint32_t)v;
        const int32_t sh = d - 32;
        uint32_t q = hi >> sh;
        const uint32_t rem = hi & ((1u << sh) - 1u);
        const uint32_t half = 1u << (sh - 1);
        if (rem > half || (rem == half && (lo != 0u || (q & 1u) != 0u))) {
            ++q;
        }
        return q;
    }
    if (d > 63) {
        return 0u; /* v < 2^63 <= half of 2^d: below half the quantum */
    }
    uint64_t q = v >> d;
    uint64_t rem = v & ((UINT64_C(1) << d) - 1u);
    uint64_t half = UINT64_C(1) << (d - 1);
    if (rem > half || (rem == half && (q & 1u) != 0u)) {
        ++q;
    }
    return q;
}

/** Round (-1)^neg * sig * 2^exp (sig != 0) to the nearest float (ties to even) and return its bits. */
static uint32_t round_pack(uint32_t neg, uint64_t sig, int32_t exp)
{
    const int32_t lead = lead_index(sig);
    const int32_t e_unb = lead + exp;       /* the value is in [2^e_unb, 2^(e_unb + 1)) */
    const uint32_t sign = neg << 31;
    if (e_unb > 127) {
        return sign | GL_F32_INF;
    }
    /* Keep 24 bits for a normal result; on the subnormal grid (quantum 2^-149) keep what lies above it. */
    int32_t drop = (e_unb >= -126) ? lead - 23 : -149 - exp;
    uint64_t mant;
    if (drop <= 0) {
        mant = sig << -drop; /* exact */
    } else {
        mant = shift_right_round(sig, drop);
    }
    if (e_unb < -126) {
        return sign | (uint32_t)mant; /* subnormal; 2^23 after rounding up is the smallest normal's bits */
    }
    /* mant in [2^23, 2^24]: adding it with its leading one carries into the exponent field (+1 for 2^23,
     * +2 for 2^24, i.e. the next binade with a zero fraction). */
    uint32_t bits = ((uint32_t)(e_unb + 126) << 23) + (uint32_t)mant;
    if (bits >= GL_F32_INF) {
        return sign | GL_F32_INF;
    }
    return sign | bits;
}

/** a * b + c for finite, non-zero a, b, c. */
static uint32_t fma_finite(uint32_t ab, uint32_t bb, uint32_t cb)
{
    gl_unpacked_t p = product(ab, bb);
    gl_unpacked_t c = addend(cb);
    gl_unpacked_t *big = &p;
    gl_unpacked_t *small = &c;
    if (c.exp > p.exp || (c.exp == p.exp && c.sig > p.sig)) {
        big = &c;
        small = &p;
    }
    uint64_t s = shift_right_sticky(small->sig, big->exp - small->exp);
    uint64_t sum;
    if (big->neg == small->neg) {
        sum = big->sig + s; /* < 2^63: both are below 2^62 */
    } else {
        sum = big->sig - s; /* >= 0: big is the larger magnitude */
        if (sum == 0u) {
            return 0u; /* exact cancellation is +0 when rounding to nearest */
        }
    }
    return round_pack(big->neg, sum, big->exp);
}

float gl_fmaf(float a, float b, float c)
{
    const uint32_t ab = f32_bits(a);
    const uint32_t bb = f32_bits(b);
    const uint32_t cb = f32_bits(c);
    const uint32_t ea = (ab >> 23) & GL_F32_EXP_MASK;
    const uint32_t eb = (bb >> 23) & GL_F32_EXP_MASK;
    const uint32_t ec = (cb >> 23) & GL_F32_EXP_MASK;
    if (ea == GL_F32_EXP_MASK || eb == GL_F32_EXP_MASK) {
        return a * b + c; /* an infinity or NaN in the product: a * b is exact (inf, NaN) */
    }
    if (ec == GL_F32_EXP_MASK) {
        return c + c; /* a finite product cannot change an infinite c; a NaN stays NaN */
    }
    if ((ab & ~GL_F32_SIGN) == 0u || (bb & ~GL_F32_SIGN) == 0u) {
        return a * b + c; /* the product is an exact signed zero */
    }
    if ((cb & ~GL_F32_SIGN) == 0u) {
        return a * b; /* the exact result is the product itself: one rounding, its own sign */
    }
    return f32_from_bits(fma_finite(ab, bb, cb));
}
