/**
 * @file gl_mav_law.c
 * @brief The integer law behind the MAVLink node of a fixed-point export (see gl_mav_law.h).
 */
#include "gl_mav_law.h"

#include <stddef.h>
#include <string.h>

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
