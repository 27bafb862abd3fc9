/**
 * @file gl_fixed.c
 * @brief The fixed-point law on integers (gl_fixed.h; docs/design.md, "Fixed point").
 *
 * Signed overflow is undefined in C, so every sum that could wrap is formed in uint64_t (modular) and read back
 * as int64_t (GCC: modular); for inputs in range the certificate proves no partial sum leaves 63 bits, so the
 * modular sum is the exact one. `>>` of a negative int64_t is GCC's arithmetic shift, as the model's. Loops over
 * the q integrators count with an int (GL_FX_Q may be 0: an unsigned `j < 0` would not compile under -Wextra).
 */
#include "gainlink/gl_fixed.h"
#include "gainlink/gl_crc32.h"

#include <stddef.h>
#include <string.h>

_Static_assert(GL_FX_SIGNALS <= 256, "signal indices are uint8_t");
_Static_assert(GL_FX_TERMS_A <= 65535, "row ends are uint16_t");

#define GL_FX_WORD_MAX ((int32_t)((1ul << (GL_FX_WORD_BITS - 1)) - 1ul))

/* (a + 2^(s-1)) >> s for s > 0, a for s = 0, a << -s for s < 0 (round half up). */
static inline int64_t rshift_round(int64_t a, int s)
{
    if (s > 0) {
        return (int64_t)((uint64_t)a + ((uint64_t)1 << (s - 1))) >> s;
    }
    return (int64_t)((uint64_t)a << -s);
}

static inline int32_t sat(int64_t x, int32_t hi, uint32_t bit, uint32_t *ovf)
{
    if (x > hi) {
        *ovf |= bit;
        return hi;
    }
    if (x < -(int64_t)hi - 1) {
        *ovf |= bit;
        return -hi - 1;
    }
    return (int32_t)x;
}

#if defined(__ARM_ARCH_6M__)
/*
 * acc += a b, exact, on a core without a 32 x 32 -> 64 multiply (Cortex-M0/M0+): with a = ah 2^16 + al and
 * b = bh 2^16 + bl (ah, bh signed, al, bl unsigned halves), a b = ah bh 2^32 + (ah bl + al bh) 2^16 + al bl, each
 * product a 16 x 16 `muls` that fits 32 bits, added into (hi, lo) with carries; 19 instructions. In C, GCC keeps
 * the 64-bit partial sums on the stack (about 65 instructions a term); a libgcc call costs more still.
 */
static inline void mac(uint32_t *lo, uint32_t *hi, int32_t a, int32_t b)
{
    uint32_t ta;
    uint32_t tb;
    uint32_t th;
    uint32_t l = *lo;
    uint32_t h = *hi;
    __asm__(".syntax unified\n\t"
            "uxth  %[ta], %[a]\n\t"
            "asrs  %[a], %[a], #16\n\t"
            "uxth  %[tb], %[b]\n\t"
            "asrs  %[b], %[b], #16\n\t"
            "movs  %[th], %[a]\n\t"
            "muls  %[th], %[b]\n\t"  /* ah bh */
            "muls  %[a], %[tb]\n\t"  /* ah bl */
            "muls  %[b], %[ta]\n\t"  /* bh al */
            "muls  %[ta], %[tb]\n\t" /* al bl */
            "adds  %[l], %[ta]\n\t"
            "adcs  %[h], %[th]\n\t"
            "lsls  %[ta], %[a], #16\n\t"
            "asrs  %[a], %[a], #16\n\t"
            "adds  %[l], %[ta]\n\t"
            "adcs  %[h], %[a]\n\t"
            "lsls  %[ta], %[b], #16\n\t"
            "asrs  %[b], %[b], #16\n\t"
            "adds  %[l], %[ta]\n\t"
            "adcs  %[h], %[b]"
            : [l] "+l"(l), [h] "+l"(h), [a] "+l"(a), [b] "+l"(b), [ta] "=&l"(ta), [tb] "=&l"(tb), [th] "=&l"(th)
            :
            : "cc");
    *lo = l;
    *hi = h;
}

#define GL_FX_MAC(lo, hi, a, b) mac(&(lo), &(hi), (a), (b))
#else
/* lo, hi += a b (the 64-bit accumulator as two words, as the M0's mac()). */
#define GL_FX_MAC(lo, hi, a, b)                                                                                      \
    do {                                                                                                             \
        const uint64_t t_ = ((((uint64_t)(hi)) << 32) | (lo)) + (uint64_t)((int64_t)(a) * (int64_t)(b));            \
        (lo) = (uint32_t)t_;                                                                                         \
        (hi) = (uint32_t)(t_ >> 32);                                                                                 \
    } while (0)
#endif

/* A term with a left shift e (a coefficient whose format is coarser than its row's allows): formed on its own. */
#define GL_FX_MAC_SHIFTED(shifted, a, b, e)                                                                          \
    do {                                                                                                             \
        uint32_t tl_ = 0u;                                                                                           \
        uint32_t th_ = 0u;                                                                                           \
        GL_FX_MAC(tl_, th_, (a), (b));                                                                               \
        (shifted) += ((((uint64_t)th_) << 32) | tl_) << (e);                                                         \
    } while (0)

#if GL_FX_UNROLLED
#include "gl_fixed_step.h" /* generated: gl_fx_row(), each row's terms written out (signals and shifts fixed) */
#endif

/* Row `row` of the sums: sum_k (coef[k] sig[signal[k]]) << shift[k], exact, rounded once by the row's shift. */
static int64_t row_sum(const gl_fixed_gains_t *g, const int32_t *sig, unsigned row)
{
#if GL_FX_UNROLLED
    const int64_t acc = gl_fx_row(g, sig, row);
#else
    uint32_t lo = 0u;
    uint32_t hi = 0u;
    uint64_t shifted = 0u;
    const unsigned end = g->row_end[row];
    for (unsigned k = row == 0u ? 0u : g->row_end[row - 1u]; k < end; ++k) {
        const unsigned e = g->shift[k];
        if (e == 0u) {
            GL_FX_MAC(lo, hi, g->coef[k], sig[g->signal[k]]);
        } else {
            GL_FX_MAC_SHIFTED(shifted, g->coef[k], sig[g->signal[k]], e);
        }
    }
    const int64_t acc = (int64_t)((((uint64_t)hi << 32) | lo) + shifted);
#endif
    return rshift_round(acc, g->row_shift[row]);
}

int32_t gl_fixed_key(float x)
{
    uint32_t b;
    memcpy(&b, &x, sizeof b);
    const int32_t mag = (int32_t)(b & 0x7FFFFFFFu);
    return (b >> 31) != 0u ? -mag : mag;
}

static int finite_bits(float x)
{
    uint32_t b;
    memcpy(&b, &x, sizeof b);
    return (b & 0x7F800000u) != 0x7F800000u;
}

/* floor(x 2^frac + 1/2) of a float in range, exactly, from its bits: rshift_round of the signed significand. */
static int32_t quantise(float x, int frac)
{
    uint32_t b;
    memcpy(&b, &x, sizeof b);
    const uint32_t field = (b >> 23) & 0xFFu;
    int32_t mant = (int32_t)(b & 0x7FFFFFu);
    int exp = (int)field - 150 + frac; /* x 2^frac = mant 2^exp */
    if (field != 0u) {
        mant |= 0x800000;
    } else {
        exp += 1; /* subnormal */
    }
    const int64_t signed_mant = (b >> 31) != 0u ? -(int64_t)mant : (int64_t)mant;
    return (int32_t)rshift_round(signed_mant, exp < -62 ? 62 : -exp);
}

/* Step 1 for one value: clip to its declared range (order keys; `bit` into *clip when clipped) and quantise. */
static gl_fx_word_t sample(float x, int32_t key_lo, int32_t key_hi, gl_fx_word_t lo, gl_fx_word_t hi, int frac,
                           uint32_t bit, uint32_t *clip)
{
    const int32_t key = gl_fixed_key(x);
    if (key < key_lo) {
        *clip |= bit;
        return lo;
    }
    if (key > key_hi) {
        *clip |= bit;
        return hi;
    }
    return (gl_fx_word_t)quantise(x, frac);
}

int gl_fixed_init(gl_fixed_loop_t *loop, const gl_fixed_gains_t *g)
{
    if (loop == NULL || g == NULL) {
        return -1;
    }
    memset(loop, 0, sizeof *loop);
    loop->g = g;
    gl_fixed_reset(loop);
    return 0;
}

void gl_fixed_reset(gl_fixed_loop_t *loop)
{
    const gl_fixed_gains_t *g = loop->g;
    memcpy(&loop->sig[GL_FX_SIG_XH], g->xh0, sizeof(int32_t) * GL_FX_N);
#if GL_FX_Q > 0
    memcpy(&loop->sig[GL_FX_SIG_Z], g->z0, sizeof(int32_t) * GL_FX_Q);
#endif
    memcpy(loop->u, g->u_safe, sizeof loop->u);
}

static void to_float(gl_fixed_loop_t *loop, float *u)
{
    for (unsigned i = 0; i < GL_FX_M; ++i) {
        u[i] = (float)loop->u[i] * loop->g->u_lsb[i];
    }
}

/* Steps 0-2: the samples into Y, R, dY; 0 when one is not finite. */
static int take_samples(gl_fixed_loop_t *loop, const float *y, const float *r)
{
    const gl_fixed_gains_t *g = loop->g;
    for (unsigned k = 0; k < GL_FX_P; ++k) {
        if (!finite_bits(y[k])) {
            return 0;
        }
    }
    for (int j = 0; j < GL_FX_Q; ++j) {
        if (!finite_bits(r[j])) {
            return 0;
        }
    }
    int32_t *s = loop->sig;
    for (unsigned k = 0; k < GL_FX_P; ++k) {
        const gl_fx_word_t Y =
            sample(y[k], g->key_y_lo[k], g->key_y_hi[k], g->y_lo[k], g->y_hi[k], g->frac_y[k], 1u << k, &loop->clip_mask);
        s[GL_FX_SIG_Y + k] = Y;
        s[GL_FX_SIG_DY + k] = sat((int64_t)Y - g->yop[k], GL_FX_WORD_MAX, GL_FX_OVF_DY, &loop->overflow_mask);
    }
    for (int j = 0; j < GL_FX_Q; ++j) {
        s[GL_FX_SIG_R + j] = sample(r[j], g->key_r_lo[j], g->key_r_hi[j], g->r_lo[j], g->r_hi[j], g->frac_r[j],
                                    1u << (GL_FX_P + j), &loop->clip_mask);
    }
    return 1;
}

/* Steps 3-5: V, the clamp, the command word U, dU and Uv - V. */
static void commands(gl_fixed_loop_t *loop)
{
    const gl_fixed_gains_t *g = loop->g;
    int32_t *s = loop->sig;
    uint32_t *ovf = &loop->overflow_mask;
    for (unsigned i = 0; i < GL_FX_M; ++i) {
        const int32_t v = sat((int64_t)g->uop_v[i] + row_sum(g, s, i), INT32_MAX, GL_FX_OVF_V, ovf);
        int32_t uv = v;
        if (v < g->lo_v[i]) {
            uv = g->lo_v[i];
        } else if (v > g->hi_v[i]) {
            uv = g->hi_v[i];
        }
        if (uv != v) {
            loop->sat_mask |= 1u << i;
        }
        const gl_fx_word_t U = (gl_fx_word_t)rshift_round(uv, g->shift_u[i]);
        loop->v[i] = v;
        loop->u[i] = U;
        s[GL_FX_SIG_DU + i] = sat((int64_t)U - g->uop_u[i], GL_FX_WORD_MAX, GL_FX_OVF_DU, ovf);
        s[GL_FX_SIG_W + i] = sat((int64_t)uv - v, INT32_MAX, GL_FX_OVF_W, ovf);
    }
}

/* Steps 6-8: the integrators and the estimate from the old state, then committed. */
static void update_state(gl_fixed_loop_t *loop)
{
    const gl_fixed_gains_t *g = loop->g;
    int32_t *s = loop->sig;
    uint32_t *ovf = &loop->overflow_mask;
    int32_t z[GL_FX_QA];
    int32_t xh[GL_FX_N];
    const int hold = g->clamp != 0u && loop->sat_mask != 0u;
    for (int j = 0; j < GL_FX_Q; ++j) {
        const int32_t zj = s[GL_FX_SIG_Z + j];
        z[j] = hold ? zj : sat((int64_t)zj + row_sum(g, s, GL_FX_M + j), INT32_MAX, GL_FX_OVF_Z, ovf);
    }
    for (unsigned i = 0; i < GL_FX_N; ++i) {
        xh[i] = sat(row_sum(g, s, GL_FX_M + GL_FX_Q + i), INT32_MAX, GL_FX_OVF_XH, ovf);
    }
    memcpy(&s[GL_FX_SIG_XH], xh, sizeof xh);
#if GL_FX_Q > 0
    memcpy(&s[GL_FX_SIG_Z], z, sizeof(int32_t) * GL_FX_Q);
#else
    (void)z;
#endif
}

uint32_t gl_fixed_step(gl_fixed_loop_t *loop, const float *y, const float *r, float *u)
{
    loop->sat_mask = 0u;
    loop->clip_mask = 0u;
    loop->overflow_mask = 0u;
    if (!take_samples(loop, y, r)) {
        for (unsigned i = 0; i < GL_FX_M; ++i) {
            loop->u[i] = loop->g->u_safe[i];
            loop->v[i] = loop->g->u_safe[i]; /* as the model: V reports the safe command on a fault */
        }
        loop->flags = GL_FX_FAULT;
        to_float(loop, u);
        return loop->flags;
    }
    commands(loop);
    update_state(loop);
    loop->flags = (loop->clip_mask != 0u ? GL_FX_CLIPPED : 0u) | (loop->overflow_mask != 0u ? GL_FX_OVERFLOW : 0u);
    to_float(loop, u);
    return loop->flags;
}

void gl_fixed_command(const gl_fixed_loop_t *loop, float *u)
{
    for (unsigned i = 0; i < GL_FX_M; ++i) {
        u[i] = (float)loop->u[i] * loop->g->u_lsb[i];
    }
}

/* Whether `count` entries of two tables are equal (the structure a set must share with the compiled one). */
#define SAME(a, b, count) (memcmp((a), (b), sizeof((a)[0]) * (size_t)(count)) == 0)

int gl_fixed_check(const gl_fixed_gains_t *g)
{
    const gl_fixed_gains_t *c = &gl_fixed_default.g;
    const int same = SAME(g->signal, c->signal, GL_FX_TERMS) && SAME(g->row_end, c->row_end, GL_FX_ROWS) &&
                     SAME(g->row_shift, c->row_shift, GL_FX_ROWS) && SAME(g->shift_u, c->shift_u, GL_FX_M) &&
                     SAME(g->frac_y, c->frac_y, GL_FX_P) && SAME(g->frac_r, c->frac_r, GL_FX_QA) &&
                     SAME(g->frac_u, c->frac_u, GL_FX_M) && SAME(g->key_y_lo, c->key_y_lo, GL_FX_P) &&
                     SAME(g->key_y_hi, c->key_y_hi, GL_FX_P) && SAME(g->key_r_lo, c->key_r_lo, GL_FX_QA) &&
                     SAME(g->key_r_hi, c->key_r_hi, GL_FX_QA) && SAME(g->y_lo, c->y_lo, GL_FX_P) &&
                     SAME(g->y_hi, c->y_hi, GL_FX_P) && SAME(g->r_lo, c->r_lo, GL_FX_QA) &&
                     SAME(g->r_hi, c->r_hi, GL_FX_QA) && SAME(g->u_lsb, c->u_lsb, GL_FX_M) && g->clamp == c->clamp;
    if (!same) {
        return -1;
    }
    for (unsigned k = 0; k < GL_FX_TERMS; ++k) {
        if (g->shift[k] > 62u) {
            return -2;
        }
    }
    for (unsigned i = 0; i < GL_FX_M; ++i) {
        if (g->lo_v[i] > g->hi_v[i]) {
            return -2;
        }
    }
    return 0;
}

/* CRC-32 (zlib's) of one int32 as its four little-endian bytes, continuing `c` (the register, not inverted). */
static uint32_t crc_word(uint32_t c, int32_t w)
{
    return gl_crc32_word(c, (uint32_t)w);
}

/* The same for `count` int32 words (count may be 0: GL_FX_Q). */
static uint32_t crc_words(uint32_t c, const int32_t *w, unsigned count)
{
    for (unsigned k = 0; k < count; ++k) {
        c = crc_word(c, w[k]);
    }
    return c;
}

/* The CRC of `count` (>= 1) entries of any integer table as int32 words. */
#define CRC_TABLE(c, table, count)                                                                                   \
    do {                                                                                                             \
        for (size_t k_ = 0; k_ < (size_t)(count); ++k_) {                                                            \
            (c) = crc_word((c), (int32_t)(table)[k_]);                                                               \
        }                                                                                                            \
    } while (0)

uint32_t gl_fixed_set_crc32(const gl_fixed_gains_t *g)
{
    uint32_t c = 0xFFFFFFFFu;
    for (unsigned k = 0; k < GL_FX_TERMS; ++k) {
        c = crc_word(c, g->coef[k]);
        c = crc_word(c, g->shift[k]);
    }
    CRC_TABLE(c, g->uop_v, GL_FX_M);
    CRC_TABLE(c, g->lo_v, GL_FX_M);
    CRC_TABLE(c, g->hi_v, GL_FX_M);
    CRC_TABLE(c, g->uop_u, GL_FX_M);
    CRC_TABLE(c, g->u_safe, GL_FX_M);
    CRC_TABLE(c, g->yop, GL_FX_P);
    CRC_TABLE(c, g->xh0, GL_FX_N);
    c = crc_words(c, g->z0, GL_FX_Q);
    return ~c;
}
