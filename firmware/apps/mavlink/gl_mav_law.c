/**
 * @file gl_mav_law.c
 * @brief The integer law behind the MAVLink node of a fixed-point export, or the scheduled law behind that of a
 *        scheduled export (see gl_mav_law.h).
 */
#include "gl_mav_law.h"

#include <stddef.h>
#include <string.h>

#if defined(GL_MAV_LAW_FIXED) && GL_MAV_LAW_FIXED

static void words_to_floats(const gl_fixed_loop_t *loop, const gl_fx_word_t *words, float *u)
{
    for (unsigned i = 0; i < GL_FX_M; ++i) {
        u[i] = (float)words[i] * loop->g->u_lsb[i];
    }
}

int gl_mav_fixed_init(gl_mav_fixed_t *law, const gl_fixed_gains_t *g, uint32_t watchdog_periods)
{
    if (law == NULL) {
        return -1;
    }
    law->missed = 0u;
    law->watchdog_periods = watchdog_periods;
    return gl_fixed_init(&law->loop, g);
}

uint64_t gl_mav_fixed_step(gl_mav_fixed_t *law, const float *y, const float *r, float *u)
{
    const uint32_t fx = gl_fixed_step(&law->loop, y, r, u);
    law->missed = 0u;
    uint64_t flags = 0u;
    flags |= (fx & GL_FX_FAULT) ? GL_MAV_FLAG_FAULT : 0u;
    flags |= (fx & GL_FX_CLIPPED) ? GL_MAV_FLAG_CLIPPED : 0u;
    flags |= (fx & GL_FX_OVERFLOW) ? GL_MAV_FLAG_OVERFLOW : 0u;
    if ((fx & GL_FX_FAULT) == 0u) {
        flags |= (uint64_t)law->loop.sat_mask << GL_MAV_SAT_SHIFT;
    }
    return flags;
}

uint64_t gl_mav_fixed_reset(gl_mav_fixed_t *law, float *u)
{
    gl_fixed_reset(&law->loop);
    law->missed = 0u;
    words_to_floats(&law->loop, law->loop.u, u);
    return GL_MAV_FLAG_RESET;
}

uint64_t gl_mav_fixed_idle(gl_mav_fixed_t *law, float *u)
{
    if (law->missed < law->watchdog_periods) {
        law->missed++;
    }
    if (law->missed >= law->watchdog_periods) { /* as gl_loop_idle(): the safe command until the next sample */
        memcpy(law->loop.u, law->loop.g->u_safe, sizeof law->loop.u);
        law->loop.sat_mask = 0u;
        words_to_floats(&law->loop, law->loop.u, u);
        return GL_MAV_FLAG_WATCHDOG;
    }
    words_to_floats(&law->loop, law->loop.u, u);
    return 0u;
}

#elif defined(GL_MAV_LAW_SCHED) && GL_MAV_LAW_SCHED

gl_status_t gl_mav_sched_init(gl_mav_sched_t *law, const gl_sched_tables_t *t, uint32_t watchdog_periods)
{
    if (law == NULL) {
        return GL_SCHED_ERR_NULL;
    }
    law->missed = 0u;
    law->watchdog_periods = watchdog_periods;
    return gl_sched_init(&law->loop, t);
}

void gl_mav_sched_retable(gl_mav_sched_t *law)
{
    gl_sched_retable(&law->loop); /* the coefficients at the held sigma come from the new tables */
}

static uint64_t sigma_flags(uint32_t f)
{
    uint64_t flags = 0u;
    flags |= (f & GL_SIGMA_HELD) ? GL_MAV_FLAG_SIGMA_HELD : 0u;
    flags |= (f & GL_SIGMA_CLIPPED) ? GL_MAV_FLAG_SIGMA_CLIPPED : 0u;
    flags |= (f & GL_SIGMA_RATE) ? GL_MAV_FLAG_SIGMA_RATE : 0u;
    return flags;
}

uint64_t gl_mav_sched_step(gl_mav_sched_t *law, const float *y, const float *r, const float *s, float *u)
{
    const gl_sched_status_t st = gl_sched_step(&law->loop, y, r, s, u);
    law->missed = 0u;
    if (st < 0) {
        return GL_MAV_FLAG_FAULT;
    }
    return sigma_flags(law->loop.sigma_flags) | ((uint64_t)law->loop.sat_mask << GL_MAV_SAT_SHIFT);
}

uint64_t gl_mav_sched_reset(gl_mav_sched_t *law, float *u)
{
    (void)gl_sched_reset(&law->loop);
    law->missed = 0u;
    memcpy(u, law->loop.u, sizeof law->loop.u);
    return GL_MAV_FLAG_RESET;
}

/** The safe command, u_op at the held sigma clamped: what the law answers a refused sample, on a copy of it (the
 *  law's state and fault count stay as they are). */
static void safe_command(const gl_mav_sched_t *law, float *u)
{
    static gl_sched_t probe; /* static: the loop is large for a stack; the node steps from one thread */
    const float nan_y[GL_P] = {[0] = __builtin_nanf("")};
    const float r[GL_Q] = {0};
    const float s[GL_EA] = {0};
    probe = law->loop;
    (void)gl_sched_step(&probe, nan_y, r, s, u);
}

uint64_t gl_mav_sched_idle(gl_mav_sched_t *law, float *u)
{
    if (law->missed < law->watchdog_periods) {
        law->missed++;
    }
    if (law->missed >= law->watchdog_periods) { /* as gl_loop_idle(): the safe command until the next sample */
        safe_command(law, u);
        memcpy(law->loop.u, u, sizeof law->loop.u);
        law->loop.sat_mask = 0u;
        return GL_MAV_FLAG_WATCHDOG;
    }
    memcpy(u, law->loop.u, sizeof law->loop.u);
    return 0u;
}

#endif
