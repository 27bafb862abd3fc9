/**
 * @file gl_can_law.c
 * @brief The float32 or the fixed-point law behind the CAN node (see gl_can_law.h).
 */
#include "gl_can_law.h"

#include <stddef.h>

#include "gl_can_layout.h"

#if defined(GL_SCHEDULED) && GL_SCHEDULED

gl_status_t gl_can_law_init(gl_can_law_t *law, uint32_t watchdog_periods)
{
    (void)watchdog_periods;
    return gl_sched_init(law, &gl_sched_default);
}

uint32_t gl_can_law_step(gl_can_law_t *law, const float *y, const float *r, const float *s, float *u,
                         uint8_t *status)
{
    gl_sched_status_t st = gl_sched_step(law, y, r, s, u);
    uint8_t bits = st == GL_SCHED_ERR_NANINF ? GL_CAN_STATUS_FAULT : 0u;
    bits |= (law->sigma_flags & GL_SIGMA_HELD) ? GL_CAN_STATUS_SIGMA_HELD : 0u;
    bits |= (law->sigma_flags & GL_SIGMA_CLIPPED) ? GL_CAN_STATUS_SIGMA_CLIPPED : 0u;
    bits |= (law->sigma_flags & GL_SIGMA_RATE) ? GL_CAN_STATUS_SIGMA_RATE : 0u;
    *status = bits;
    return st == GL_SCHED_SATURATED ? law->sat_mask : 0u;
}

#elif defined(GL_CAN_LAW_FIXED) && GL_CAN_LAW_FIXED

gl_status_t gl_can_law_init(gl_can_law_t *law, uint32_t watchdog_periods)
{
    (void)watchdog_periods; /* the node steps only on a sample: there is no idle period to count */
    return gl_fixed_init(law, &gl_fixed_gains_default) == 0 ? GL_OK : GL_ERR_NULL;
}

uint32_t gl_can_law_step(gl_can_law_t *law, const float *y, const float *r, const float *s, float *u,
                         uint8_t *status)
{
    (void)s;
    uint32_t flags = gl_fixed_step(law, y, r, u);
    uint8_t bits = 0u;
    bits |= (flags & GL_FX_FAULT) ? GL_CAN_STATUS_FAULT : 0u;
    bits |= (flags & GL_FX_CLIPPED) ? GL_CAN_STATUS_CLIPPED : 0u;
    bits |= (flags & GL_FX_OVERFLOW) ? GL_CAN_STATUS_OVERFLOW : 0u;
    *status = bits;
    return (flags & GL_FX_FAULT) ? 0u : law->sat_mask;
}

#else

gl_status_t gl_can_law_init(gl_can_law_t *law, uint32_t watchdog_periods)
{
    return gl_loop_init(law, &gl_gains_default, watchdog_periods);
}

uint32_t gl_can_law_step(gl_can_law_t *law, const float *y, const float *r, const float *s, float *u,
                         uint8_t *status)
{
    (void)s;
    gl_status_t st = gl_loop_step(law, y, r, u);
    *status = st == GL_ERR_NANINF ? GL_CAN_STATUS_FAULT : 0u;
    return st == GL_SATURATED ? law->sat_mask : 0u;
}

#endif
