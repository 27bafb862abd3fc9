/**
 * @file gl_loop.c
 * @brief The per-sample step of the gainlink control law, reset, watchdog and gain swap.
 */
#include <stddef.h>
#include <string.h>

#include "gl_internal.h"

/* Fixed dimensions let the compiler unroll every loop of the step completely. */
#define GL_UNROLL _Pragma("GCC unroll 64")

gl_status_t gl_loop_init(gl_loop_t *loop, const gl_gains_t *gains, uint32_t watchdog_periods)
{
    if (loop == NULL || gains == NULL) {
        return GL_ERR_NULL;
    }
    if (watchdog_periods == 0u) {
        return GL_ERR_RANGE;
    }
    gl_coeffs_t *bank = &loop->bank[0];
    gl_status_t st = gl_coeffs_derive(gains, bank);
    if (st != GL_OK) {
        return st;
    }
    loop->active = bank;
    loop->pending = 0u;
    loop->watchdog_periods = watchdog_periods;
    loop->faults = 0u;
    loop->swaps = 0u;
    return gl_loop_reset(loop);
}

gl_status_t gl_loop_reset(gl_loop_t *loop)
{
    if (loop == NULL || loop->active == NULL) {
        return GL_ERR_NULL;
    }
    const gl_coeffs_t *c = loop->active;
    memcpy(loop->xh, c->xh0, sizeof loop->xh);
    memcpy(loop->z, c->z0, sizeof loop->z);
    memcpy(loop->u, c->u_safe, sizeof loop->u);
    loop->sat_mask = 0u;
    loop->missed = 0u;
    return GL_OK;
}

gl_status_t gl_loop_stage(gl_loop_t *loop, const gl_gains_t *gains)
{
    if (loop == NULL || gains == NULL || loop->active == NULL) {
        return GL_ERR_NULL;
    }
    if (loop->pending != 0u) {
        return GL_ERR_BUSY;
    }
    gl_coeffs_t *inactive = (loop->active == &loop->bank[0]) ? &loop->bank[1] : &loop->bank[0];
    gl_status_t st = gl_coeffs_derive(gains, inactive);
    if (st != GL_OK) {
        return st;
    }
    __atomic_thread_fence(__ATOMIC_RELEASE); /* the bank is complete before the flag is seen */
    loop->pending = 1u;
    return GL_OK;
}

uint32_t gl_loop_active_crc32(const gl_loop_t *loop)
{
    return (loop == NULL || loop->active == NULL) ? 0u : loop->active->crc32;
}

gl_status_t gl_loop_step(gl_loop_t *loop, const float *y, const float *r, float *u)
{
    if (loop == NULL || y == NULL || u == NULL || (GL_Q > 0 && r == NULL)) {
        return GL_ERR_NULL;
    }
    if (loop->pending != 0u) {
        loop->active = (loop->active == &loop->bank[0]) ? &loop->bank[1] : &loop->bank[0];
        loop->pending = 0u;
        loop->swaps++;
    }
    const gl_coeffs_t *c = loop->active;
    loop->missed = 0u;

    float ys[GL_P];
    float rs[GL_QA];
    /* Finiteness probe: x * 0 is (+/-)0 for finite x and NaN for Inf/NaN, so the sum is NaN iff any is. */
    float probe = 0.0f;
    GL_UNROLL for (size_t i = 0; i < GL_P; ++i)
    {
        ys[i] = y[i];
        probe = GL_FMA(ys[i], 0.0f, probe);
    }
#if GL_Q > 0
    GL_UNROLL for (size_t j = 0; j < GL_Q; ++j)
    {
        rs[j] = r[j];
        probe = GL_FMA(rs[j], 0.0f, probe);
    }
#else
    (void)r;
    rs[0] = 0.0f;
#endif
    if (probe != probe) {
        memcpy(u, c->u_safe, sizeof(float) * GL_M);
        memcpy(loop->u, c->u_safe, sizeof loop->u);
        loop->sat_mask = 0u;
        loop->faults++;
        return GL_ERR_NANINF;
    }

    float xh[GL_N];
    GL_UNROLL for (size_t j = 0; j < GL_N; ++j)
    {
        xh[j] = loop->xh[j];
    }
    float z[GL_QA];
    GL_UNROLL for (size_t j = 0; j < GL_QA; ++j)
    {
        z[j] = loop->z[j];
    }

    /* v = -(Kx xh + Ky y + Ki z), with the gains stored negated. */
    float v[GL_M];
    float us[GL_M];
    uint32_t sat = 0u;
    GL_UNROLL for (size_t i = 0; i < GL_M; ++i)
    {
        float acc = c->Kx[i][0] * xh[0];
        GL_UNROLL for (size_t j = 1; j < GL_N; ++j)
        {
            acc = GL_FMA(c->Kx[i][j], xh[j], acc);
        }
#if GL_OBSERVER_FORM == GL_FORM_CURRENT
        GL_UNROLL for (size_t k = 0; k < GL_P; ++k)
        {
            acc = GL_FMA(c->Ky[i][k], ys[k], acc);
        }
#endif
#if GL_Q > 0
        GL_UNROLL for (size_t j = 0; j < GL_Q; ++j)
        {
            acc = GL_FMA(c->Ki[i][j], z[j], acc);
        }
#endif
        v[i] = acc;
        float ui = acc < c->u_min[i] ? c->u_min[i] : acc;
        ui = ui > c->u_max[i] ? c->u_max[i] : ui;
        sat |= (uint32_t)(ui != acc) << i;
        us[i] = ui;
    }

#if GL_Q > 0
    /* z += Ts (r - Ci y) [+ Kaw (u - v)]; clamp mode skips the step when any input saturated. */
#if GL_ANTI_WINDUP == GL_AW_CLAMP
    if (sat == 0u)
#endif
    {
        GL_UNROLL for (size_t j = 0; j < GL_Q; ++j)
        {
            float e = rs[j];
            GL_UNROLL for (size_t k = 0; k < GL_P; ++k)
            {
                e = GL_FMA(c->Ci[j][k], ys[k], e);
            }
            float zj = GL_FMA(c->Ts, e, z[j]);
#if GL_ANTI_WINDUP == GL_AW_BACKCALC
            GL_UNROLL for (size_t k = 0; k < GL_M; ++k)
            {
                zj = GL_FMA(c->Kaw[j][k], us[k] - v[k], zj);
            }
#endif
            loop->z[j] = zj;
        }
    }
#endif

    /* xh = F xh + G u + L y  (F = Ad - L Cd, G = Bd - L Dd). */
    GL_UNROLL for (size_t i = 0; i < GL_N; ++i)
    {
        float acc = c->F[i][0] * xh[0];
        GL_UNROLL for (size_t j = 1; j < GL_N; ++j)
        {
            acc = GL_FMA(c->F[i][j], xh[j], acc);
        }
        GL_UNROLL for (size_t k = 0; k < GL_M; ++k)
        {
            acc = GL_FMA(c->G[i][k], us[k], acc);
        }
        GL_UNROLL for (size_t k = 0; k < GL_P; ++k)
        {
            acc = GL_FMA(c->L[i][k], ys[k], acc);
        }
        loop->xh[i] = acc;
    }

    GL_UNROLL for (size_t i = 0; i < GL_M; ++i)
    {
        u[i] = us[i];
        loop->u[i] = us[i];
    }
    (void)v; /* used only by back-calculation */
    (void)z; /* used only with integral action */
    (void)rs;
    loop->sat_mask = sat;
    return sat != 0u ? GL_SATURATED : GL_OK;
}

gl_status_t gl_loop_idle(gl_loop_t *loop, float *u)
{
    if (loop == NULL || u == NULL || loop->active == NULL) {
        return GL_ERR_NULL;
    }
    if (loop->missed < loop->watchdog_periods) {
        loop->missed++;
    }
    if (loop->missed >= loop->watchdog_periods) {
        memcpy(loop->u, loop->active->u_safe, sizeof loop->u);
        memcpy(u, loop->u, sizeof loop->u);
        loop->sat_mask = 0u;
        return GL_ERR_WATCHDOG;
    }
    memcpy(u, loop->u, sizeof loop->u);
    return GL_OK;
}

gl_status_t gl_loop_run_block(gl_loop_t *loop, uint32_t count, const float *Y, const float *R, float *U,
                              uint32_t *SAT, float *XH, float *Z, uint8_t *FAULT)
{
    if (loop == NULL || (count > 0u && Y == NULL) || (GL_Q > 0 && count > 0u && R == NULL)) {
        return GL_ERR_NULL;
    }
    float u[GL_M];
    for (uint32_t k = 0; k < count; ++k) {
        const float *r = (GL_Q > 0) ? &R[(size_t)k * GL_QA] : NULL;
        gl_status_t st = gl_loop_step(loop, &Y[(size_t)k * GL_P], r, u);
        if (U != NULL) {
            memcpy(&U[(size_t)k * GL_M], u, sizeof u);
        }
        if (SAT != NULL) {
            SAT[k] = loop->sat_mask;
        }
        if (XH != NULL) {
            memcpy(&XH[(size_t)k * GL_N], loop->xh, sizeof loop->xh);
        }
        if (Z != NULL) {
            memcpy(&Z[(size_t)k * GL_QA], loop->z, sizeof loop->z);
        }
        if (FAULT != NULL) {
            FAULT[k] = (uint8_t)(st == GL_ERR_NANINF);
        }
    }
    return GL_OK;
}
