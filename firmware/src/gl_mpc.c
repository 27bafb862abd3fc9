/**
 * @file gl_mpc.c
 * @brief The MPC law's step (gl_mpc.h; docs/design.md, "MPC (the fourth law)"): observer, integrators, ADMM on
 *        per-stage Riccati gains. Every sum is a chain from its first term, one GL_FMA a term, in the order of
 *        gl_mpc.h (gainlink.laws.mpc.solver and .step run the same operations).
 */
#include "gainlink/gl_mpc.h"
#include "gainlink/gl_crc32.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "gl_fma.h"

/* Fixed dimensions: the inner loops unroll completely (the stage loops stay loops). */
#define GL_UNROLL _Pragma("GCC unroll 64")
#define GL_COLD __attribute__((noinline))
/* The three parts of an iteration stay functions of their own: the instruction counter counts each per call
 * (bench/mpc_cost.py: the cost of an iteration, and so of a step at the cap). */
#define GL_PASS __attribute__((noinline))

_Static_assert(sizeof(gl_mpc_tables_t) % sizeof(float) == 0, "gl_mpc_tables_t must hold floats only");

static int all_finite(const float *x, uint32_t count)
{
    for (uint32_t k = 0; k < count; ++k) {
        if (!isfinite(x[k])) {
            return 0;
        }
    }
    return 1;
}

/** v clamped to [lo, hi] (lo <= hi, as gl_mpc_check requires), as two selects that the hard-float cores compile to a
 * compare and a predicated move (an IT block or vsel): no branch, so the instructions an iteration executes do not
 * depend on which side of its box each element falls (docs/design.md, "MPC": the cost bound; the disassembly check
 * in gainlink.firmware.branches fails if a compiler turns a select into a branch). Equal to
 * v < lo ? lo : (v > hi ? hi : v) for every v, NaN included. */
static inline float clamp(float v, float lo, float hi)
{
    const float a = v < lo ? lo : v;
    return a > hi ? hi : a;
}

gl_mpc_status_t gl_mpc_check(const gl_mpc_tables_t *t)
{
    if (t == NULL) {
        return GL_MPC_ERR_NULL;
    }
    if (!all_finite((const float *)(const void *)t, (uint32_t)(sizeof *t / sizeof(float)))) {
        return GL_MPC_ERR_NANINF;
    }
    if (!(t->rho > 0.0f && t->rho_x > 0.0f && t->kappa >= 0.0f && t->kappa <= 1.0f && t->Ts > 0.0f)) {
        return GL_MPC_ERR_RANGE;
    }
    for (uint32_t i = 0; i < GL_M; ++i) {
        if (!(t->u_min[i] <= t->u_max[i] && t->lo_u[i] <= t->hi_u[i])) {
            return GL_MPC_ERR_RANGE;
        }
    }
#if GL_NC > 0
    for (uint32_t r = 0; r < GL_NC; ++r) {
        if (!(t->lo_x[r] < t->hi_x[r])) {
            return GL_MPC_ERR_RANGE;
        }
    }
#endif
    return GL_MPC_OK;
}

gl_mpc_status_t gl_mpc_init(gl_mpc_t *loop, const gl_mpc_tables_t *tables)
{
    if (loop == NULL || tables == NULL) {
        return GL_MPC_ERR_NULL;
    }
    const gl_mpc_status_t st = gl_mpc_check(tables);
    if (st != GL_MPC_OK) {
        return st;
    }
    memset(loop, 0, sizeof *loop);
    loop->t = tables;
    return gl_mpc_reset(loop);
}

void gl_mpc_safe(const gl_mpc_t *loop, float *u)
{
    const gl_mpc_tables_t *t = loop->t;
    for (uint32_t i = 0; i < GL_M; ++i) {
        u[i] = clamp(t->u_op[i], t->u_min[i], t->u_max[i]);
    }
}

gl_mpc_status_t gl_mpc_reset(gl_mpc_t *loop)
{
    if (loop == NULL || loop->t == NULL) {
        return GL_MPC_ERR_NULL;
    }
    memcpy(loop->xh, loop->t->xh0, sizeof loop->xh);
    memcpy(loop->z, loop->t->z0, sizeof loop->z);
    memset(loop->zu, 0, sizeof loop->zu);
    memset(loop->yu, 0, sizeof loop->yu);
    memset(loop->zx, 0, sizeof loop->zx);
    memset(loop->yx, 0, sizeof loop->yx);
    gl_mpc_safe(loop, loop->out);
    loop->sat_mask = 0u;
    loop->iterations = 0u;
    loop->capped = 0u;
    return GL_MPC_OK;
}

/** p = rho_x Hx' (yx[j] - zx[j]): the linear term of x_{j+1}'s slack (zeros without boxes). */
static inline void box_term(const gl_mpc_t *loop, uint32_t j, float *p)
{
    GL_UNROLL
    for (uint32_t i = 0; i < GL_NX; ++i) {
        p[i] = 0.0f;
    }
#if GL_NC > 0
    const gl_mpc_tables_t *t = loop->t;
    float w[GL_NC];
    GL_UNROLL
    for (uint32_t r = 0; r < GL_NC; ++r) {
        w[r] = t->rho_x * (loop->yx[j][r] - loop->zx[j][r]);
    }
    GL_UNROLL
    for (uint32_t i = 0; i < GL_NX; ++i) {
        float acc = p[i];
        GL_UNROLL
        for (uint32_t r = 0; r < GL_NC; ++r) {
            acc = GL_FMA(t->Hx[r * GL_NX + i], w[r], acc);
        }
        p[i] = acc;
    }
#else
    (void)loop;
    (void)j;
#endif
}

/* One stage of each pass is a function of its own: inside it every coefficient is a short offset from the base
 * register of its table (a vldr with an immediate); with the stage loop around an inlined body, GCC hoisted every
 * coefficient's address out of the loop and kept them on the stack (a load more per multiply-add). Its vectors
 * are restrict (no output aliases an input): the vector a pass multiplies stays in registers. */
#if GL_NX * (GL_NX + GL_M) > 96
#define GL_STAGE_FN static __attribute__((noinline))
#else /* a small stage costs less than a call: inlined (the pendulum's 5 x 6 stage: 43.4k instructions a step at
       * worst on the M4F against 56.1k as a function) */
#define GL_STAGE_FN static inline __attribute__((always_inline))
#endif

/** Stage k of the backward pass: g = r + B'p, d = C1 g, and (k > 0) pn = q + A'p - K'g. */
GL_STAGE_FN void backward_stage(const float *restrict A, const float *restrict B, const float *restrict K,
                                    const float *restrict C1, float rho, const float *restrict yu,
                                    const float *restrict zu, const float *restrict p, const float *restrict q,
                                    float *restrict d, float *restrict pn)
{
    float g[GL_M];
    GL_UNROLL
    for (uint32_t i = 0; i < GL_M; ++i) {
        float acc = rho * (yu[i] - zu[i]);
        GL_UNROLL
        for (uint32_t j = 0; j < GL_NX; ++j) {
            acc = GL_FMA(B[j * GL_M + i], p[j], acc);
        }
        g[i] = acc;
    }
    GL_UNROLL
    for (uint32_t i = 0; i < GL_M; ++i) {
        float acc = 0.0f;
        GL_UNROLL
        for (uint32_t l = 0; l < GL_M; ++l) {
            acc = GL_FMA(C1[i * GL_M + l], g[l], acc);
        }
        d[i] = acc;
    }
    if (pn == NULL) {
        return;
    }
    GL_UNROLL
    for (uint32_t j = 0; j < GL_NX; ++j) {
        float acc = q[j];
        GL_UNROLL
        for (uint32_t i = 0; i < GL_NX; ++i) {
            acc = GL_FMA(A[i * GL_NX + j], p[i], acc);
        }
        GL_UNROLL
        for (uint32_t i = 0; i < GL_M; ++i) {
            acc = GL_FMA(-K[i * GL_NX + j], g[i], acc);
        }
        pn[j] = acc;
    }
}

/** The backward pass: d[k] for every stage. */
static GL_PASS void backward(gl_mpc_t *loop)
{
    const gl_mpc_tables_t *t = loop->t;
    float p[2][GL_NX];
    float q[GL_NX];
    uint32_t at = 0u;
    box_term(loop, GL_H - 1u, p[0]);
    for (uint32_t kk = GL_H; kk-- > 0u;) {
        float *pn = NULL;
        if (kk > 0u) {
            box_term(loop, kk - 1u, q);
            pn = p[at ^ 1u];
        }
        backward_stage(t->A, t->B, t->K[kk], t->C1[kk], t->rho, loop->yu[kk], loop->zu[kk], p[at], q, loop->d[kk],
                       pn);
        at ^= 1u;
    }
}

/** Stage k of the forward pass: u = -d - K x, xn = A x + B u, c = Hx xn. */
GL_STAGE_FN void forward_stage(const float *restrict A, const float *restrict B, const float *restrict K,
                                   const float *restrict Hx, const float *restrict d, const float *restrict x,
                                   float *restrict u, float *restrict xn, float *restrict c)
{
    GL_UNROLL
    for (uint32_t i = 0; i < GL_M; ++i) {
        float acc = -d[i];
        GL_UNROLL
        for (uint32_t j = 0; j < GL_NX; ++j) {
            acc = GL_FMA(-K[i * GL_NX + j], x[j], acc);
        }
        u[i] = acc;
    }
    GL_UNROLL
    for (uint32_t i = 0; i < GL_NX; ++i) {
        float acc = 0.0f;
        GL_UNROLL
        for (uint32_t j = 0; j < GL_NX; ++j) {
            acc = GL_FMA(A[i * GL_NX + j], x[j], acc);
        }
        GL_UNROLL
        for (uint32_t l = 0; l < GL_M; ++l) {
            acc = GL_FMA(B[i * GL_M + l], u[l], acc);
        }
        xn[i] = acc;
    }
#if GL_NC > 0
    GL_UNROLL
    for (uint32_t r = 0; r < GL_NC; ++r) {
        float acc = 0.0f;
        GL_UNROLL
        for (uint32_t j = 0; j < GL_NX; ++j) {
            acc = GL_FMA(Hx[r * GL_NX + j], xn[j], acc);
        }
        c[r] = acc;
    }
#else
    (void)Hx;
    (void)c;
#endif
}

/** The forward pass from x0: the moves u[k] and the box rows c[k] of x_{k+1}. */
static GL_PASS void forward(gl_mpc_t *loop, const float *x0)
{
    const gl_mpc_tables_t *t = loop->t;
    float x[2][GL_NX];
    uint32_t at = 0u;
    memcpy(x[0], x0, sizeof x[0]);
    for (uint32_t k = 0; k < GL_H; ++k) {
        forward_stage(t->A, t->B, t->K[k], t->Hx, loop->d[k], x[at], loop->u[k], x[at ^ 1u], loop->c[k]);
        at ^= 1u;
    }
}

/** Slack, dual and both residual tests of every stage; 1 when every residual is within its threshold. */
static GL_PASS int slacks(gl_mpc_t *loop)
{
    const gl_mpc_tables_t *t = loop->t;
    int done = 1;
    for (uint32_t k = 0; k < GL_H; ++k) {
        GL_UNROLL
        for (uint32_t i = 0; i < GL_M; ++i) {
            const float u = loop->u[k][i];
            const float v = u + loop->yu[k][i];
            const float z = clamp(v, t->lo_u[i], t->hi_u[i]);
            const float e = u - z;
            const float dual = t->rho * fabsf(z - loop->zu[k][i]);
            loop->yu[k][i] = loop->yu[k][i] + e;
            loop->zu[k][i] = z;
            done &= (fabsf(e) <= t->eps_pu[i]) & (dual <= t->eps_du[i]);
        }
#if GL_NC > 0
        GL_UNROLL
        for (uint32_t r = 0; r < GL_NC; ++r) {
            const float c = loop->c[k][r];
            const float v = c + loop->yx[k][r];
            /* kappa of the way back to the box, as one chain whatever the side: inside, v - v = +0 and the
             * multiply-add returns v exactly (the model's three cases, bit for bit) */
            const float z = GL_FMA(-t->kappa, v - clamp(v, t->lo_x[r], t->hi_x[r]), v);
            const float e = c - z;
            const float dual = t->rho_x * fabsf(z - loop->zx[k][r]);
            loop->yx[k][r] = loop->yx[k][r] + e;
            loop->zx[k][r] = z;
            done &= (fabsf(e) <= t->eps_px[r]) & (dual <= t->eps_dx[r]);
        }
#endif
    }
    return done;
}

/** ADMM from the warm start: iterations until the stopping test holds or the cap. A function of its own, so its
 * iteration counter is not a register the step shares with its other tests (the disassembly check, bench/mpc_cost.py,
 * finds the stopping test as the one branch here that the numbers decide). */
static GL_PASS void solve(gl_mpc_t *loop, const float *x0)
{
    int done = 0;
    uint32_t it = 0u;
    while (it < GL_MPC_MAX_ITER) {
        ++it;
        backward(loop);
        forward(loop, x0);
        done = slacks(loop);
        if (done) {
            break;
        }
    }
    loop->iterations = it;
    loop->capped = done ? 0u : 1u;
}

/** acc[i] += sum_j sign M[i][j] x[j], one chain per row (acc holds each chain's start). */
static inline void chain(float *acc, const float *Mx, const float *x, uint32_t rows, uint32_t cols, float sign)
{
    for (uint32_t i = 0; i < rows; ++i) {
        float a = acc[i];
        for (uint32_t j = 0; j < cols; ++j) {
            a = GL_FMA(sign * Mx[i * cols + j], x[j], a);
        }
        acc[i] = a;
    }
}

/** The integrators after the command: z += Ts e (+ Kaw (u - v)), per the anti-windup mode. */
static void integrate(gl_mpc_t *loop, const float *ys, const float *rs, const float *u, const float *v)
{
#if GL_Q > 0
    const gl_mpc_tables_t *t = loop->t;
    float e[GL_Q];
    memcpy(e, rs, sizeof e);
    chain(e, t->Ci, ys, GL_Q, GL_P, -1.0f);
#if GL_ANTI_WINDUP == GL_MPC_AW_CLAMP
    uint32_t hold = 0u; /* any input clamped: the integrators hold (a select, not a return: the cost bound) */
    for (uint32_t i = 0; i < GL_M; ++i) {
        hold |= (uint32_t)(u[i] != v[i]);
    }
    for (uint32_t j = 0; j < GL_Q; ++j) {
        const float zn = GL_FMA(t->Ts, e[j], loop->z[j]);
        loop->z[j] = hold ? loop->z[j] : zn;
    }
#else
    for (uint32_t j = 0; j < GL_Q; ++j) {
        loop->z[j] = GL_FMA(t->Ts, e[j], loop->z[j]);
    }
#endif
#if GL_ANTI_WINDUP == GL_MPC_AW_BACKCALC
    float w[GL_M];
    for (uint32_t i = 0; i < GL_M; ++i) {
        w[i] = u[i] - v[i];
    }
    chain(loop->z, t->Kaw, w, GL_Q, GL_M, 1.0f);
#endif
#else
    (void)loop;
    (void)ys;
    (void)rs;
    (void)u;
    (void)v;
#endif
}

/** The estimate after the command (xe: the estimate the solver started from). */
static void estimate(gl_mpc_t *loop, const float *xe, const float *dy, const float *du)
{
    const gl_mpc_tables_t *t = loop->t;
    float xn[GL_N] = {0};
#if GL_OBSERVER_FORM == GL_MPC_FORM_CURRENT
    (void)dy;
    chain(xn, t->Ad, xe, GL_N, GL_N, 1.0f);
    chain(xn, t->Bd, du, GL_N, GL_M, 1.0f);
#else
    (void)xe;
    float innov[GL_P];
    memcpy(innov, dy, sizeof innov);
    chain(innov, t->Cd, loop->xh, GL_P, GL_N, -1.0f);
    chain(innov, t->Dd, du, GL_P, GL_M, -1.0f);
    chain(xn, t->Ad, loop->xh, GL_N, GL_N, 1.0f);
    chain(xn, t->Bd, du, GL_N, GL_M, 1.0f);
    chain(xn, t->L, innov, GL_N, GL_P, 1.0f);
#endif
    memcpy(loop->xh, xn, sizeof xn);
}

/** The warm start for the next step: every stage one earlier, the last kept. */
static void shift(gl_mpc_t *loop)
{
    memmove(loop->zu[0], loop->zu[1], sizeof loop->zu - sizeof loop->zu[0]);
    memmove(loop->yu[0], loop->yu[1], sizeof loop->yu - sizeof loop->yu[0]);
#if GL_NC > 0
    memmove(loop->zx[0], loop->zx[1], sizeof loop->zx - sizeof loop->zx[0]);
    memmove(loop->yx[0], loop->yx[1], sizeof loop->yx - sizeof loop->yx[0]);
#endif
}

static GL_COLD gl_mpc_status_t refuse(gl_mpc_t *loop, float *u)
{
    gl_mpc_safe(loop, u);
    memcpy(loop->out, u, sizeof loop->out);
    loop->sat_mask = 0u;
    loop->iterations = 0u;
    loop->capped = 0u;
    loop->faults++;
    return GL_MPC_ERR_NANINF;
}

/** The command from the first move: v = u_op + u[0], clamped; the saturation bits. */
static uint32_t command(const gl_mpc_t *loop, float *us, float *v)
{
    const gl_mpc_tables_t *t = loop->t;
    uint32_t sat = 0u;
    for (uint32_t i = 0; i < GL_M; ++i) {
        v[i] = t->u_op[i] + loop->u[0][i];
        const float ui = clamp(v[i], t->u_min[i], t->u_max[i]);
        const float z0 = loop->zu[0][i];
        /* | rather than ||: no branch (the cost bound) */
        const uint32_t on = (uint32_t)(ui != v[i]) | (uint32_t)(z0 == t->lo_u[i]) | (uint32_t)(z0 == t->hi_u[i]);
        sat |= on << i;
        us[i] = ui;
    }
    return sat;
}

gl_mpc_status_t gl_mpc_step(gl_mpc_t *loop, const float *y, const float *r, float *u)
{
    if (loop == NULL || loop->t == NULL || y == NULL || u == NULL || (GL_Q > 0 && r == NULL)) {
        return GL_MPC_ERR_NULL;
    }
    const gl_mpc_tables_t *t = loop->t;
    float ys[GL_P];
    float rs[GL_MPC_QA] = {0};
    int finite = 1;
    for (uint32_t k = 0; k < GL_P; ++k) {
        ys[k] = y[k];
        finite &= isfinite(ys[k]) != 0;
    }
#if GL_Q > 0
    for (uint32_t j = 0; j < GL_Q; ++j) {
        rs[j] = r[j];
        finite &= isfinite(rs[j]) != 0;
    }
#endif
    if (!finite) {
        return refuse(loop, u);
    }
    float dy[GL_P];
    for (uint32_t k = 0; k < GL_P; ++k) {
        dy[k] = ys[k] - t->y_op[k];
    }
    float x0[GL_NX];
    memcpy(x0, loop->xh, sizeof loop->xh);
#if GL_OBSERVER_FORM == GL_MPC_FORM_CURRENT
    float innov[GL_P];
    memcpy(innov, dy, sizeof innov);
    chain(innov, t->Cd, loop->xh, GL_P, GL_N, -1.0f);
    chain(x0, t->M, innov, GL_N, GL_P, 1.0f);
#endif
#if GL_Q > 0
    for (uint32_t j = 0; j < GL_Q; ++j) {
        x0[GL_N + j] = loop->z[j];
    }
#endif
    solve(loop, x0);
    float us[GL_M];
    float v[GL_M];
    const uint32_t sat = command(loop, us, v);
    integrate(loop, ys, rs, us, v);
    float du[GL_M];
    for (uint32_t i = 0; i < GL_M; ++i) {
        du[i] = us[i] - t->u_op[i];
    }
    estimate(loop, x0, dy, du);
    shift(loop);
    memcpy(u, us, sizeof us);
    memcpy(loop->out, us, sizeof us);
    loop->sat_mask = sat;
    return sat != 0u ? GL_MPC_SATURATED : GL_MPC_OK;
}

uint32_t gl_mpc_tables_crc32(const gl_mpc_tables_t *tables)
{
    return gl_crc32_bytes(tables, sizeof *tables);
}

void gl_mpc_state(const gl_mpc_t *loop, float *out)
{
    uint32_t at = 0u;
    for (uint32_t i = 0; i < GL_N; ++i) {
        out[at++] = loop->xh[i];
    }
#if GL_Q > 0
    for (uint32_t j = 0; j < GL_Q; ++j) {
        out[at++] = loop->z[j];
    }
#endif
    for (uint32_t k = 0; k < GL_H; ++k) {
        for (uint32_t i = 0; i < GL_M; ++i) {
            out[at++] = loop->zu[k][i];
        }
    }
    for (uint32_t k = 0; k < GL_H; ++k) {
        for (uint32_t i = 0; i < GL_M; ++i) {
            out[at++] = loop->yu[k][i];
        }
    }
#if GL_NC > 0
    for (uint32_t k = 0; k < GL_H; ++k) {
        for (uint32_t r = 0; r < GL_NC; ++r) {
            out[at++] = loop->zx[k][r];
        }
    }
    for (uint32_t k = 0; k < GL_H; ++k) {
        for (uint32_t r = 0; r < GL_NC; ++r) {
            out[at++] = loop->yx[k][r];
        }
    }
#endif
}
