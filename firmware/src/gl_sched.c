/**
 * @file gl_sched.c
 * @brief The scheduled law's step (gl_sched.h; docs/design.md, "Scheduled law"): sigma, interpolation, velocity form.
 */
#include "gainlink/gl_sched.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "gl_fma.h"

/* Fixed dimensions let the compiler unroll every loop of the step completely. */
#define GL_UNROLL _Pragma("GCC unroll 64")

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
    loop->c_valid = 0u;
    return GL_SCHED_OK;
}

/** Sigma after the filter and the rate limit (steps 2 of the law; started loops only). */
static float shape_sigma(gl_sched_t *loop, float c, uint32_t *flags)
{
    const gl_sched_tables_t *t = loop->t;
#if GL_SIGMA_FILTERED
    loop->sigma_f = GL_FMA(t->alpha, c - loop->sigma_f, loop->sigma_f);
#else
    loop->sigma_f = c;
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

/** Step 2 of the law: the sigma this step uses (held, clipped, filtered, rate-limited); updates the held sigma. */
static float next_sigma(gl_sched_t *loop, float raw)
{
    const float *S = loop->t->S;
    uint32_t flags = 0u;
    float sigma = loop->sigma;
    if (!isfinite(raw)) {
        flags = GL_SIGMA_HELD;
    } else {
        float c = raw < S[0] ? S[0] : (raw > S[GL_NPTS - 1] ? S[GL_NPTS - 1] : raw);
        flags = (c != raw) ? GL_SIGMA_CLIPPED : 0u;
        if (loop->started == 0u) {
            loop->sigma_f = c;
            sigma = c;
        } else {
            sigma = shape_sigma(loop, c, &flags);
        }
    }
    loop->sigma = sigma;
    loop->sigma_flags = flags;
    return sigma;
}

/** Step 3: the coefficients at sigma into loop->c (kept while sigma does not change). */
static void interpolate(gl_sched_t *loop, float sigma)
{
    if (loop->c_valid != 0u && loop->c_sigma == sigma) {
        return;
    }
    float lam;
    const uint32_t i = interval(loop->t->S, sigma, &lam);
    const gl_sched_tables_t *t = loop->t;
    gl_sched_coeffs_t *c = &loop->c;
    lerp(c->Kx, t->Kx[i], t->Kx[i + 1u], GL_M * GL_N, lam);
#if GL_OBSERVER_FORM == GL_SCHED_FORM_CURRENT
    lerp(c->Ky, t->Ky[i], t->Ky[i + 1u], GL_M * GL_P, lam);
#endif
    lerp(c->Kz, t->Kz[i], t->Kz[i + 1u], GL_M * GL_Q, lam);
    lerp(c->F, t->F[i], t->F[i + 1u], GL_N * GL_N, lam);
    lerp(c->G, t->G[i], t->G[i + 1u], GL_N * GL_M, lam);
    lerp(c->Ly, t->Ly[i], t->Ly[i + 1u], GL_N * GL_P, lam);
    loop->c_sigma = sigma;
    loop->c_valid = 1u;
}

/** The command: v = u_prev - (Kx delta + Ky dy + Kz e_prev), clamped; du = u - u_prev. Returns the saturation bits. */
static uint32_t command(gl_sched_t *loop, const float *dy, float *u, float *du)
{
    const gl_sched_coeffs_t *c = &loop->c;
    const gl_sched_tables_t *t = loop->t;
    uint32_t sat = 0u;
    GL_UNROLL
    for (uint32_t i = 0; i < GL_M; ++i) {
        float acc = c->Kx[i * GL_N] * loop->delta[0];
        GL_UNROLL
        for (uint32_t j = 1; j < GL_N; ++j) {
            acc = GL_FMA(c->Kx[i * GL_N + j], loop->delta[j], acc);
        }
#if GL_OBSERVER_FORM == GL_SCHED_FORM_CURRENT
        GL_UNROLL
        for (uint32_t k = 0; k < GL_P; ++k) {
            acc = GL_FMA(c->Ky[i * GL_P + k], dy[k], acc);
        }
#else
        (void)dy;
#endif
        GL_UNROLL
        for (uint32_t j = 0; j < GL_Q; ++j) {
            acc = GL_FMA(c->Kz[i * GL_Q + j], loop->e_prev[j], acc);
        }
        const float v = loop->u_prev[i] - acc;
        u[i] = v;
        if (v < t->u_min[i]) {
            u[i] = t->u_min[i];
            sat |= 1u << i;
        } else if (v > t->u_max[i]) {
            u[i] = t->u_max[i];
            sat |= 1u << i;
        }
        du[i] = u[i] - loop->u_prev[i];
    }
    return sat;
}

/** delta = F delta + G du + Ly dy, one row at a time. */
static void estimate(gl_sched_t *loop, const float *du, const float *dy)
{
    const gl_sched_coeffs_t *c = &loop->c;
    float next[GL_N];
    GL_UNROLL
    for (uint32_t i = 0; i < GL_N; ++i) {
        float acc = c->F[i * GL_N] * loop->delta[0];
        GL_UNROLL
        for (uint32_t j = 1; j < GL_N; ++j) {
            acc = GL_FMA(c->F[i * GL_N + j], loop->delta[j], acc);
        }
        GL_UNROLL
        for (uint32_t k = 0; k < GL_M; ++k) {
            acc = GL_FMA(c->G[i * GL_M + k], du[k], acc);
        }
        GL_UNROLL
        for (uint32_t k = 0; k < GL_P; ++k) {
            acc = GL_FMA(c->Ly[i * GL_P + k], dy[k], acc);
        }
        next[i] = acc;
    }
    memcpy(loop->delta, next, sizeof next);
}

/** e_prev = r - Ci y, y_prev = y, u_prev = u. */
static void remember(gl_sched_t *loop, const float *y, const float *r, const float *u)
{
    const float *Ci = loop->t->Ci;
    GL_UNROLL
    for (uint32_t j = 0; j < GL_Q; ++j) {
        float e = r[j];
        GL_UNROLL
        for (uint32_t k = 0; k < GL_P; ++k) {
            e = GL_FMA(-Ci[j * GL_P + k], y[k], e);
        }
        loop->e_prev[j] = e;
    }
    memcpy(loop->y_prev, y, sizeof loop->y_prev);
    memcpy(loop->u_prev, u, sizeof loop->u_prev);
}

/** The first valid sample after a reset starts the law where it is: no kick. */
static void start(gl_sched_t *loop, const float *y, float sigma)
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
static gl_sched_status_t refuse(gl_sched_t *loop, float *u)
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

gl_sched_status_t gl_sched_step(gl_sched_t *loop, const float *y, const float *r, const float *s, float *u)
{
    if (loop == NULL || loop->t == NULL || y == NULL || r == NULL || u == NULL || (GL_E > 0 && s == NULL)) {
        return GL_SCHED_ERR_NULL;
    }
    if (!all_finite(y, GL_P) || !all_finite(r, GL_Q)) {
        return refuse(loop, u);
    }
#if GL_SIGMA_EXTERNAL
    const float sigma = next_sigma(loop, s[GL_SIGMA_INDEX]);
#else
    (void)s;
    const float sigma = next_sigma(loop, y[GL_SIGMA_INDEX]);
#endif
    if (loop->started == 0u) {
        start(loop, y, sigma);
    }
    interpolate(loop, sigma);
    float dy[GL_P];
    float du[GL_M];
    GL_UNROLL
    for (uint32_t k = 0; k < GL_P; ++k) {
        dy[k] = y[k] - loop->y_prev[k];
    }
    const uint32_t sat = command(loop, dy, u, du);
    estimate(loop, du, dy);
    remember(loop, y, r, u);
    memcpy(loop->u, u, sizeof loop->u);
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
    out[1] = loop->sigma_f;
    out[2] = (loop->started != 0u) ? 1.0f : 0.0f;
}

gl_sched_status_t gl_sched_run_block(gl_sched_t *loop, uint32_t count, const float *Y, const float *R,
                                     const float *S, float *U, uint32_t *SAT, uint32_t *SFLAGS, float *STATE,
                                     int32_t *STATUS)
{
    if (loop == NULL || Y == NULL || R == NULL || (GL_E > 0 && S == NULL)) {
        return GL_SCHED_ERR_NULL;
    }
    float u[GL_M];
    for (uint32_t k = 0; k < count; ++k) {
        const float *s = (GL_E > 0) ? &S[k * GL_EA] : NULL;
        const gl_sched_status_t st = gl_sched_step(loop, &Y[k * GL_P], &R[k * GL_Q], s, u);
        if (st == GL_SCHED_ERR_NULL) {
            return st;
        }
        if (U != NULL) {
            memcpy(&U[k * GL_M], u, sizeof u);
        }
        if (SAT != NULL) {
            SAT[k] = loop->sat_mask;
        }
        if (SFLAGS != NULL) {
            SFLAGS[k] = loop->sigma_flags;
        }
        if (STATE != NULL) {
            gl_sched_state(loop, &STATE[k * GL_SCHED_STATE_LEN]);
        }
        if (STATUS != NULL) {
            STATUS[k] = (int32_t)st;
        }
    }
    return GL_SCHED_OK;
}
