/**
 * @file gl_sched.c
 * @brief The scheduled law's step (gl_sched.h; docs/design.md, "Scheduled law"): sigma, interpolation, velocity form.
 */
#include "gainlink/gl_sched.h"
#include "gainlink/gl_crc32.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "gl_fma.h"

/* Fixed dimensions let the compiler unroll every loop of the step completely. */
#define GL_UNROLL _Pragma("GCC unroll 64")
/* Rare work (a reset's first sample, a refused one, entering an interval) kept out of the step's body: inlined, it
 * would cost every step a stack frame and spills. */
#define GL_COLD __attribute__((noinline))

static int all_finite(const float *x, uint32_t count)
{
    for (uint32_t k = 0; k < count; ++k) {
        if (!isfinite(x[k])) {
            return 0;
        }
    }
    return 1;
}

static int increasing(const float *S)
{
    for (uint32_t k = 0; k + 1u < GL_NPTS; ++k) {
        if (!(S[k] < S[k + 1u])) {
            return 0;
        }
    }
    return 1;
}

/** GL_SCHED_ERR_NANINF when any number of the tables is not finite, GL_SCHED_ERR_RANGE when one is out of range. */
static gl_sched_status_t check_tables(const gl_sched_tables_t *t)
{
    if (!all_finite((const float *)(const void *)t, (uint32_t)(sizeof *t / sizeof(float)))) {
        return GL_SCHED_ERR_NANINF;
    }
    if (!increasing(t->S) || !(t->alpha > 0.0f && t->alpha <= 1.0f) || !(t->rate_step > 0.0f)) {
        return GL_SCHED_ERR_RANGE;
    }
    for (uint32_t i = 0; i < GL_M; ++i) {
        if (t->u_min[i] > t->u_max[i]) {
            return GL_SCHED_ERR_RANGE;
        }
    }
    return GL_SCHED_OK;
}

_Static_assert(sizeof(gl_sched_tables_t) % sizeof(float) == 0, "gl_sched_tables_t must hold floats only");

gl_sched_status_t gl_sched_init(gl_sched_t *loop, const gl_sched_tables_t *tables)
{
    if (loop == NULL || tables == NULL) {
        return GL_SCHED_ERR_NULL;
    }
    gl_sched_status_t st = check_tables(tables);
    if (st != GL_SCHED_OK) {
        return st;
    }
    memset(loop, 0, sizeof *loop);
    loop->t = tables;
    return gl_sched_reset(loop);
}

/** The interval i with S[i] <= sigma <= S[i+1] (the last one at SN) and lam = (sigma - S[i]) / (S[i+1] - S[i]). */
static uint32_t interval(const float *S, float sigma, float *lam)
{
    uint32_t i = 0;
    while (i + 2u < GL_NPTS && sigma >= S[i + 1u]) {
        ++i;
    }
    *lam = (sigma - S[i]) / (S[i + 1u] - S[i]);
    return i;
}

/** out[k] = X0[k] + lam (X1[k] - X0[k]), one fused multiply-add each. */
static inline void lerp(float *out, const float *X0, const float *X1, uint32_t count, float lam)
{
    GL_UNROLL
    for (uint32_t k = 0; k < count; ++k) {
        out[k] = GL_FMA(lam, X1[k] - X0[k], X0[k]);
    }
}

/** u_op interpolated at (i, lam) and clamped into the limits: the start and the safe command. */
static void trim(const gl_sched_tables_t *t, uint32_t i, float lam, float *u)
{
    lerp(u, t->u_op[i], t->u_op[i + 1u], GL_M, lam);
    for (uint32_t k = 0; k < GL_M; ++k) {
        u[k] = u[k] < t->u_min[k] ? t->u_min[k] : (u[k] > t->u_max[k] ? t->u_max[k] : u[k]);
    }
}

gl_sched_status_t gl_sched_reset(gl_sched_t *loop)
{
    if (loop == NULL || loop->t == NULL) {
        return GL_SCHED_ERR_NULL;
    }
    const gl_sched_tables_t *t = loop->t;
    memset(loop->delta, 0, sizeof loop->delta);
    memset(loop->y_prev, 0, sizeof loop->y_prev);
    memset(loop->e_prev, 0, sizeof loop->e_prev);
    loop->sigma = t->S[0];
    loop->sigma_f = t->S[0];
    loop->started = 0u;
    trim(t, 0u, 0.0f, loop->u_prev);
    memcpy(loop->u, loop->u_prev, sizeof loop->u);
    loop->sat_mask = 0u;
    loop->sigma_flags = 0u;
    gl_sched_retable(loop); /* the start may land in any interval: nothing cached */
    return GL_SCHED_OK;
}

/* Without a filter and a rate limit, sigma_f is sigma on every step: the step keeps sigma only, and
 * gl_sched_state() reports it as sigma_f too. */
#define GL_SIGMA_SHAPED (GL_SIGMA_FILTERED || GL_SIGMA_RATE_LIMITED)

/** Sigma after the filter and the rate limit (steps 2 of the law; started loops only). */
static float shape_sigma(gl_sched_t *loop, float c, uint32_t *flags)
{
    const gl_sched_tables_t *t = loop->t;
#if GL_SIGMA_FILTERED
    loop->sigma_f = GL_FMA(t->alpha, c - loop->sigma_f, loop->sigma_f);
#elif GL_SIGMA_SHAPED
    loop->sigma_f = c;
#else
    return c;
#endif
#if GL_SIGMA_RATE_LIMITED
    const float d = loop->sigma_f - loop->sigma;
    if (fabsf(d) > t->rate_step) {
        *flags |= GL_SIGMA_RATE;
        return loop->sigma + (d > 0.0f ? t->rate_step : -t->rate_step);
    }
#else
    (void)t;
    (void)flags;
#endif
    return loop->sigma_f;
}

/** Step 2 of the law: the sigma this step uses (held, clipped, filtered, rate-limited); updates the held sigma.
 *  A sigma read from the measurement is finite already (the step refused the sample otherwise). */
static float next_sigma(gl_sched_t *loop, float raw)
{
    const float *S = loop->t->S;
    uint32_t flags = 0u;
    float sigma = loop->sigma;
    if (GL_SIGMA_EXTERNAL && !isfinite(raw)) {
        flags = GL_SIGMA_HELD;
    } else {
        float c = raw; /* clipped exactly when raw lies outside [S1, SN] (c != raw then) */
        if (raw < S[0]) {
            c = S[0];
            flags = GL_SIGMA_CLIPPED;
        } else if (raw > S[GL_NPTS - 1]) {
            c = S[GL_NPTS - 1];
            flags = GL_SIGMA_CLIPPED;
        }
        if (loop->started == 0u) {
            if (GL_SIGMA_SHAPED) {
                loop->sigma_f = c;
            }
            sigma = c;
        } else {
            sigma = shape_sigma(loop, c, &flags);
        }
    }
    loop->sigma = sigma;
    loop->sigma_flags = flags;
    return sigma;
}

/** x0[k] = X0[k] and d[k] = X1[k] - X0[k]: the interval's start and the differences the interpolation multiplies,
 *  once per interval entered. */
static inline void split(float *x0, float *d, const float *X0, const float *X1, uint32_t count)
{
    GL_UNROLL
    for (uint32_t k = 0; k < count; ++k) {
        x0[k] = X0[k];
        d[k] = X1[k] - X0[k];
    }
}

/** Step 3's interval i for sigma into the cache (x0 = X[i], d = X[i+1] - X[i], S[i], S[i+1] - S[i]). */
static GL_COLD void enter_interval(gl_sched_t *loop, float sigma)
{
    const gl_sched_tables_t *t = loop->t;
    float lam;
    const uint32_t i = interval(t->S, sigma, &lam);
    gl_sched_coeffs_t *x0 = &loop->x0;
    gl_sched_coeffs_t *d = &loop->d;
    split(x0->Kx, d->Kx, t->Kx[i], t->Kx[i + 1u], GL_M * GL_N);
#if GL_OBSERVER_FORM == GL_SCHED_FORM_CURRENT
    split(x0->Ky, d->Ky, t->Ky[i], t->Ky[i + 1u], GL_M * GL_P);
#endif
    split(x0->Kz, d->Kz, t->Kz[i], t->Kz[i + 1u], GL_M * GL_Q);
    split(x0->F, d->F, t->F[i], t->F[i + 1u], GL_N * GL_N);
    split(x0->G, d->G, t->G[i], t->G[i + 1u], GL_N * GL_M);
    split(x0->Ly, d->Ly, t->Ly[i], t->Ly[i + 1u], GL_N * GL_P);
    loop->c_s0 = t->S[i];
    loop->c_width = t->S[i + 1u] - t->S[i];
    /* lam's bits as an unsigned integer are below 0x3f800000 exactly for +0 <= lam < 1, and (sigma - S[i]) and the
     * division round monotonically: sigma < S[i] gives lam < 0 or -0, sigma >= S[i+1] gives lam >= 1. So the test
     * keeps only sigmas of this interval (the last one also holds S[N]: lam = 1). A width that overflowed keeps
     * nothing: every step searches again. A sigma it turns away (-0 at S[i] = 0) is searched for again: same i. */
    loop->c_span = isfinite(loop->c_width) ? (i + 2u == GL_NPTS ? 0x3f800001u : 0x3f800000u) : 0u;
    loop->c_limit = loop->fixed_ok != 0u ? loop->c_span : 0u; /* else every moving step interpolates all */
    loop->c_inner = loop->c_limit != 0u ? 0x3f800000u : 0u;    /* lam < 1: S[i] <= sigma < S[i+1] */
}

/** out[k] = fmaf(lam, D[k], X0[k]): lerp() on the cached differences. */
static void lerp_d(float *out, const float *X0, const float *D, uint32_t count, float lam)
{
    for (uint32_t k = 0; k < count; ++k) {
        out[k] = GL_FMA(lam, D[k], X0[k]);
    }
}

/** c = fmaf(lam, d, x0), every coefficient: what the law runs while sigma stands. */
static void fill(gl_sched_t *loop, float lam)
{
    gl_sched_coeffs_t *c = &loop->c;
    const gl_sched_coeffs_t *x0 = &loop->x0;
    const gl_sched_coeffs_t *d = &loop->d;
    lerp_d(c->Kx, x0->Kx, d->Kx, GL_M * GL_N, lam);
#if GL_OBSERVER_FORM == GL_SCHED_FORM_CURRENT
    lerp_d(c->Ky, x0->Ky, d->Ky, GL_M * GL_P, lam);
#endif
    lerp_d(c->Kz, x0->Kz, d->Kz, GL_M * GL_Q, lam);
    lerp_d(c->F, x0->F, d->F, GL_N * GL_N, lam);
    lerp_d(c->G, x0->G, d->G, GL_N * GL_M, lam);
    lerp_d(c->Ly, x0->Ly, d->Ly, GL_N * GL_P, lam);
}

/* The law reads its coefficients from c (fused = GL_LERP_NONE: sigma stands, c holds them) or interpolates them
 * where it multiplies (fmaf(lam, d, x0), the same float32 value as c's, never stored): every one (GL_LERP_ALL), or
 * only those that vary between the points (GL_LERP_VARYING: a coefficient of a GL_SCHED_FIXED_* mask is x0's, and
 * fmaf(lam, +0, x) == x exactly for such an x, the same at every point and not -0). Inlined with fused constant:
 * specialised copies of the law, a moving sigma costing one load and one fused multiply-add per varying
 * coefficient. */
#define GL_INLINE static inline __attribute__((always_inline))
#define GL_LERP_NONE 0
#define GL_LERP_ALL 1
#define GL_LERP_VARYING 2

/** Coefficient k of a group: a[k], or fmaf(lam, b[k], a[k]) (a = x0, b = d) as fused and fixed (the group's mask)
 *  say. */
GL_INLINE float coef(const float *a, const float *b, float lam, int fused, uint32_t fixed, uint32_t k)
{
    const int is_fixed = k < 32u && ((fixed >> k) & 1u) != 0u;
    const int varies = fused == GL_LERP_ALL || (fused == GL_LERP_VARYING && !is_fixed);
    return varies ? GL_FMA(lam, b[k], a[k]) : a[k];
}

/** The loop's state the law reads, in locals (the outputs may alias nothing it still needs). */
typedef struct gl_sched_now {
    float delta[GL_N];
    float u_prev[GL_M];
    float dy[GL_P];
    float e_prev[GL_Q];
} gl_sched_now_t;

/** The command: v = u_prev - (Kx delta + Ky dy + Kz e_prev), clamped; du = u - u_prev. Returns the saturation bits. */
GL_INLINE uint32_t command(const gl_sched_t *loop, const gl_sched_coeffs_t *a, const gl_sched_coeffs_t *b,
                           float lam, int fused, const gl_sched_now_t *x, float *u, float *du)
{
    const gl_sched_tables_t *t = loop->t;
    uint32_t sat = 0u;
    GL_UNROLL
    for (uint32_t i = 0; i < GL_M; ++i) {
        float acc = coef(a->Kx, b->Kx, lam, fused, GL_SCHED_FIXED_KX, i * GL_N) * x->delta[0];
        GL_UNROLL
        for (uint32_t j = 1; j < GL_N; ++j) {
            acc = GL_FMA(coef(a->Kx, b->Kx, lam, fused, GL_SCHED_FIXED_KX, i * GL_N + j), x->delta[j], acc);
        }
#if GL_OBSERVER_FORM == GL_SCHED_FORM_CURRENT
        GL_UNROLL
        for (uint32_t k = 0; k < GL_P; ++k) {
            acc = GL_FMA(coef(a->Ky, b->Ky, lam, fused, GL_SCHED_FIXED_KY, i * GL_P + k), x->dy[k], acc);
        }
#endif
        GL_UNROLL
        for (uint32_t j = 0; j < GL_Q; ++j) {
            acc = GL_FMA(coef(a->Kz, b->Kz, lam, fused, GL_SCHED_FIXED_KZ, i * GL_Q + j), x->e_prev[j], acc);
        }
        const float v = x->u_prev[i] - acc;
        float ui = v;
        if (v < t->u_min[i]) {
            ui = t->u_min[i];
            sat |= 1u << i;
        } else if (v > t->u_max[i]) {
            ui = t->u_max[i];
            sat |= 1u << i;
        }
        u[i] = ui;
        du[i] = ui - x->u_prev[i];
    }
    return sat;
}

/** delta = F delta + G du + Ly dy, one row at a time (into loop->delta: x holds the old delta). */
GL_INLINE void estimate(gl_sched_t *loop, const gl_sched_coeffs_t *a, const gl_sched_coeffs_t *b, float lam,
                        int fused, const gl_sched_now_t *x, const float *du)
{
    GL_UNROLL
    for (uint32_t i = 0; i < GL_N; ++i) {
        float acc = coef(a->F, b->F, lam, fused, GL_SCHED_FIXED_F, i * GL_N) * x->delta[0];
        GL_UNROLL
        for (uint32_t j = 1; j < GL_N; ++j) {
            acc = GL_FMA(coef(a->F, b->F, lam, fused, GL_SCHED_FIXED_F, i * GL_N + j), x->delta[j], acc);
        }
        GL_UNROLL
        for (uint32_t k = 0; k < GL_M; ++k) {
            acc = GL_FMA(coef(a->G, b->G, lam, fused, GL_SCHED_FIXED_G, i * GL_M + k), du[k], acc);
        }
        GL_UNROLL
        for (uint32_t k = 0; k < GL_P; ++k) {
            acc = GL_FMA(coef(a->Ly, b->Ly, lam, fused, GL_SCHED_FIXED_LY, i * GL_P + k), x->dy[k], acc);
        }
        loop->delta[i] = acc;
    }
}

/** e_prev = r - Ci y, y_prev = y, u_prev = u. */
GL_INLINE void remember(gl_sched_t *loop, const float *ys, const float *rs, const float *u)
{
    const float *Ci = loop->t->Ci;
    GL_UNROLL
    for (uint32_t j = 0; j < GL_Q; ++j) {
        float e = rs[j];
        GL_UNROLL
        for (uint32_t k = 0; k < GL_P; ++k) {
            e = GL_FMA(-Ci[j * GL_P + k], ys[k], e);
        }
        loop->e_prev[j] = e;
    }
    GL_UNROLL
    for (uint32_t k = 0; k < GL_P; ++k) {
        loop->y_prev[k] = ys[k];
    }
    GL_UNROLL
    for (uint32_t i = 0; i < GL_M; ++i) {
        loop->u_prev[i] = u[i];
    }
}

/** Step 4 on the finite samples ys, rs with the coefficients of (a, b, lam, fused): the command into u, the
 *  state updated. Returns the saturation bits. */
GL_INLINE uint32_t law(gl_sched_t *loop, const gl_sched_coeffs_t *a, const gl_sched_coeffs_t *b, float lam,
                       int fused, const float *ys, const float *rs, float *u)
{
    gl_sched_now_t x; /* element by element: registers, not a copy through the stack */
    GL_UNROLL
    for (uint32_t j = 0; j < GL_N; ++j) {
        x.delta[j] = loop->delta[j];
    }
    GL_UNROLL
    for (uint32_t i = 0; i < GL_M; ++i) {
        x.u_prev[i] = loop->u_prev[i];
    }
    GL_UNROLL
    for (uint32_t j = 0; j < GL_Q; ++j) {
        x.e_prev[j] = loop->e_prev[j];
    }
    GL_UNROLL
    for (uint32_t k = 0; k < GL_P; ++k) {
        x.dy[k] = ys[k] - loop->y_prev[k];
    }
    float du[GL_M];
    const uint32_t sat = command(loop, a, b, lam, fused, &x, u, du);
    estimate(loop, a, b, lam, fused, &x, du);
    remember(loop, ys, rs, u);
    return sat;
}

/** lam the slow way, when the fast test failed: sigma left the cached interval (searched again), or the tables break
 *  the GL_SCHED_FIXED_* masks (c_limit 0: the caller interpolates every coefficient). */
static GL_COLD float searched(gl_sched_t *loop, float sigma)
{
    float lam = (sigma - loop->c_s0) / loop->c_width;
    uint32_t bits;
    memcpy(&bits, &lam, sizeof bits);
    if (bits >= loop->c_span) {
        enter_interval(loop, sigma);
        lam = (sigma - loop->c_s0) / loop->c_width;
    }
    return lam;
}

/** c_sigma when c holds no coefficients: a NaN's bits, never those of a sigma (always finite). */
#define GL_SCHED_C_NONE 0x7fc00000u

/** Steps 3 and 4: the coefficients at sigma (c while sigma stands, interpolated in place while it moves); held is
 *  the sigma of the last valid step. lam is (sigma - S[i]) / (S[i+1] - S[i]) as interval() computes it (the same
 *  float32 operations on the same values). */
static uint32_t law_at(gl_sched_t *loop, float sigma, float held, const float *ys, const float *rs, float *u)
{
    uint32_t bits;
    memcpy(&bits, &sigma, sizeof bits);
    uint32_t last;
    memcpy(&last, &held, sizeof last);
    const int stands = bits == last;
    if (!stands || loop->c_sigma != bits) {
        float lam = (sigma - loop->c_s0) / loop->c_width;
        uint32_t lbits;
        memcpy(&lbits, &lam, sizeof lbits);
        const int fast = lbits < loop->c_limit; /* in the cached interval, and the tables hold the masks */
        if (!fast) {
            lam = searched(loop, sigma);
        }
        if (!stands) {
            if (fast) {
                return law(loop, &loop->x0, &loop->d, lam, GL_LERP_VARYING, ys, rs, u);
            }
            return law(loop, &loop->x0, &loop->d, lam, GL_LERP_ALL, ys, rs, u);
        }
        fill(loop, lam); /* sigma stood still since the last step: keep its coefficients from now on */
        loop->c_sigma = bits;
    }
    return law(loop, &loop->c, &loop->c, 0.0f, GL_LERP_NONE, ys, rs, u);
}

/** 1 when the coefficients mask names (bit k, k < 32) are the same float32 at every point and not -0. */
static int fixed_group(const float *X, uint32_t count, uint32_t mask)
{
    for (uint32_t k = 0; k < count && k < 32u; ++k) {
        if (((mask >> k) & 1u) == 0u) {
            continue;
        }
        uint32_t b0;
        memcpy(&b0, &X[k], sizeof b0);
        for (uint32_t i = 1; i < GL_NPTS; ++i) {
            uint32_t bi;
            memcpy(&bi, &X[i * count + k], sizeof bi);
            if (bi != b0 || b0 == 0x80000000u) {
                return 0;
            }
        }
    }
    return 1;
}

/** 1 when the tables hold the GL_SCHED_FIXED_* masks the step was compiled with. */
static int fixed_hold(const gl_sched_tables_t *t)
{
    return fixed_group(&t->Kx[0][0], GL_M * GL_N, GL_SCHED_FIXED_KX) &&
           fixed_group(&t->Ky[0][0], GL_M * GL_P, GL_SCHED_FIXED_KY) &&
           fixed_group(&t->Kz[0][0], GL_M * GL_Q, GL_SCHED_FIXED_KZ) &&
           fixed_group(&t->F[0][0], GL_N * GL_N, GL_SCHED_FIXED_F) &&
           fixed_group(&t->G[0][0], GL_N * GL_M, GL_SCHED_FIXED_G) &&
           fixed_group(&t->Ly[0][0], GL_N * GL_P, GL_SCHED_FIXED_LY);
}

void gl_sched_retable(gl_sched_t *loop)
{
    if (loop != NULL && loop->t != NULL) {
        loop->c_sigma = GL_SCHED_C_NONE;
        loop->c_limit = 0u;
        loop->c_inner = 0u;
        loop->c_span = 0u;
        loop->fixed_ok = (uint32_t)fixed_hold(loop->t);
    }
}

/** The first valid sample after a reset starts the law where it is: no kick. */
static GL_COLD void start(gl_sched_t *loop, const float *y, float sigma)
{
    float lam;
    const uint32_t i = interval(loop->t->S, sigma, &lam);
    memcpy(loop->y_prev, y, sizeof loop->y_prev);
    trim(loop->t, i, lam, loop->u_prev);
    memset(loop->e_prev, 0, sizeof loop->e_prev);
    memset(loop->delta, 0, sizeof loop->delta);
    loop->started = 1u;
}

/** The safe command on a refused sample: u_op at the held sigma, clamped. */
static GL_COLD gl_sched_status_t refuse(gl_sched_t *loop, float *u)
{
    float lam;
    const uint32_t i = interval(loop->t->S, loop->sigma, &lam);
    trim(loop->t, i, lam, u);
    memcpy(loop->u, u, sizeof loop->u);
    loop->sat_mask = 0u;
    loop->sigma_flags = 0u;
    loop->faults++;
    return GL_SCHED_ERR_NANINF;
}

/** ys = y, rs = r (locals the law reads); 0 when any of them is not finite. The probe y0 - y0 is 0 for a finite
 *  y0 and NaN otherwise; probe * x stays 0 only while every further x is finite (0 * inf is NaN): one subtraction
 *  and a multiplication per further value, no fmaf (a library call on a host without FMA instructions). */
static int load_finite(const float *y, const float *r, float *ys, float *rs)
{
    ys[0] = y[0];
    float probe = ys[0] - ys[0];
    GL_UNROLL
    for (uint32_t k = 1; k < GL_P; ++k) {
        ys[k] = y[k];
        probe = probe * ys[k];
    }
    GL_UNROLL
    for (uint32_t j = 0; j < GL_Q; ++j) {
        rs[j] = r[j];
        probe = probe * rs[j];
    }
    return probe == probe;
}

/** Steps 2 to 4 for a sigma without filter or rate limit that moved and lies in the cached interval (then inside
 *  the envelope: not clipped, sigma = raw): what next_sigma() and law_at() would do, without their tests. lam < 1
 *  on every interval here (the last one's lam = 1 may be a clipped raw). Returns 0, nothing done, otherwise. */
GL_INLINE int moving(gl_sched_t *loop, float raw, const float *ys, const float *rs, float *u, uint32_t *sat)
{
    uint32_t bits;
    memcpy(&bits, &raw, sizeof bits);
    uint32_t last;
    memcpy(&last, &loop->sigma, sizeof last);
    if (GL_SIGMA_SHAPED || bits == last) { /* a standing sigma: its coefficients may be kept */
        return 0;
    }
    const float lam = (raw - loop->c_s0) / loop->c_width;
    uint32_t lbits;
    memcpy(&lbits, &lam, sizeof lbits);
    if (lbits < loop->c_inner && loop->started != 0u) {
        loop->sigma = raw;
        loop->sigma_flags = 0u;
        *sat = law(loop, &loop->x0, &loop->d, lam, GL_LERP_VARYING, ys, rs, u);
        return 1;
    }
    return 0;
}

gl_sched_status_t gl_sched_step(gl_sched_t *loop, const float *y, const float *r, const float *s, float *u)
{
    if (loop == NULL || loop->t == NULL || y == NULL || r == NULL || u == NULL || (GL_E > 0 && s == NULL)) {
        return GL_SCHED_ERR_NULL;
    }
    float ys[GL_P];
    float rs[GL_Q];
    if (!load_finite(y, r, ys, rs)) {
        return refuse(loop, u);
    }
#if GL_SIGMA_EXTERNAL
    const float raw = s[GL_SIGMA_INDEX];
#else
    (void)s;
    const float raw = ys[GL_SIGMA_INDEX];
#endif
    float us[GL_M];
    uint32_t sat;
    if (!moving(loop, raw, ys, rs, us, &sat)) {
        const float held = loop->sigma;
        const float sigma = next_sigma(loop, raw);
        if (loop->started == 0u) {
            start(loop, y, sigma); /* y: ys is a copy the law keeps in registers */
        }
        sat = law_at(loop, sigma, held, ys, rs, us);
    }
    GL_UNROLL
    for (uint32_t i = 0; i < GL_M; ++i) {
        u[i] = us[i];
        loop->u[i] = us[i];
    }
    loop->sat_mask = sat;
    return sat != 0u ? GL_SCHED_SATURATED : GL_SCHED_OK;
}

void gl_sched_state(const gl_sched_t *loop, float *out)
{
    memcpy(out, loop->delta, sizeof loop->delta);
    out += GL_N;
    memcpy(out, loop->u_prev, sizeof loop->u_prev);
    out += GL_M;
    memcpy(out, loop->y_prev, sizeof loop->y_prev);
    out += GL_P;
    memcpy(out, loop->e_prev, sizeof loop->e_prev);
    out += GL_Q;
    out[0] = loop->sigma;
    out[1] = GL_SIGMA_SHAPED ? loop->sigma_f : loop->sigma;
    out[2] = (loop->started != 0u) ? 1.0f : 0.0f;
}

gl_sched_status_t gl_sched_check(const gl_sched_tables_t *tables)
{
    if (tables == NULL) {
        return GL_SCHED_ERR_NULL;
    }
    const gl_sched_status_t st = check_tables(tables);
    if (st != GL_SCHED_OK) {
        return st;
    }
    return fixed_hold(tables) ? GL_SCHED_OK : GL_SCHED_ERR_DIMS;
}

uint32_t gl_sched_tables_crc32(const gl_sched_tables_t *tables)
{
    return gl_crc32_bytes(tables, sizeof *tables);
}

void gl_sched_safe(const gl_sched_t *loop, float *u)
{
    float lam;
    const uint32_t i = interval(loop->t->S, loop->sigma, &lam);
    trim(loop->t, i, lam, u);
}
