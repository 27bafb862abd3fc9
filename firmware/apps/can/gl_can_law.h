/**
 * @file gl_can_law.h
 * @brief The law the CAN node runs, chosen when it is compiled from what the export holds:
 *        - a scheduled artifact's export (gl_gains.h with GL_SCHEDULED 1): the scheduled loop (gl_sched.h), its
 *          sigma read from the measured output the schedule names or from the external scheduling signals, which
 *          a sample then carries after its references (GL_CAN_EXTRA values);
 *        - a fixed-point export (gl_fixed_gains.c, `[implementation] numeric = "q31" | "q15"`; apps/can/CMakeLists.txt
 *          then defines GL_CAN_LAW_FIXED=1, for the host app and the Cortex-M images' slcan node): the integer loop
 *          (gl_fixed.h) the artifact certifies;
 *        - otherwise the float32 loop (gl_loop.h), as it always was.
 *
 * All take the same float samples and return float commands; what they report becomes the command frames' status
 * byte and saturation mask: a refused (non-finite) sample sets GL_CAN_STATUS_FAULT, a clamped input its `sat` bit;
 * the fixed law also sets GL_CAN_STATUS_CLIPPED (a sample or reference outside its declared range, clipped) and
 * GL_CAN_STATUS_OVERFLOW (its second-line saturation fired: the certificate says it never does in range); the
 * scheduled law GL_CAN_STATUS_SIGMA_HELD / _CLIPPED / _RATE (its sigma flags). No allocation: the law lives in the
 * node's static storage.
 */
#ifndef GAINLINK_GL_CAN_LAW_H
#define GAINLINK_GL_CAN_LAW_H

#include <stdint.h>

#include "gl_gains.h" /* generated: says whether the law is scheduled */

#if defined(GL_SCHEDULED) && GL_SCHEDULED
#include "gainlink/gl_sched.h"
/** Values a sample carries after the references: the external scheduling signals (GL_E, sigma's among them). */
#define GL_CAN_EXTRA GL_E
/** The law's state: the scheduled loop. */
typedef gl_sched_t gl_can_law_t;
/** The node's status type and codes (gl_sched_status_t has gl_status_t's values). */
typedef gl_sched_status_t gl_status_t;
#define GL_OK GL_SCHED_OK
#define GL_QA ((GL_Q) > 0 ? (GL_Q) : 1)     /**< as gl_loop.h */
#define GL_WATCHDOG_PERIODS_DEFAULT 1u      /**< unused: the node steps only on a sample */
#define GL_CAN_LAW_NAME "scheduled-float32" /**< What the ready line names (law=). */
#elif defined(GL_CAN_LAW_FIXED) && GL_CAN_LAW_FIXED
#define GL_CAN_EXTRA 0
#include "gainlink/gl_loop.h"
#include "gainlink/gl_fixed.h"
/** The law's state: the integer loop. */
typedef gl_fixed_loop_t gl_can_law_t;
#if GL_NUMERIC_Q31
#define GL_CAN_LAW_NAME "q31"
#else
#define GL_CAN_LAW_NAME "q15"
#endif
#else
#define GL_CAN_EXTRA 0
#include "gainlink/gl_loop.h"
/** The law's state: the float32 loop. */
typedef gl_loop_t gl_can_law_t;
#define GL_CAN_LAW_NAME "float32"
#endif

/**
 * @brief Start the law on the compiled gains.
 * @param[out] law              The law.
 * @param[in]  watchdog_periods Idle periods before the float loop's safe command (unused by the other laws).
 * @return GL_OK, or the law's refusal of the compiled gains.
 */
gl_status_t gl_can_law_init(gl_can_law_t *law, uint32_t watchdog_periods);

/**
 * @brief One step on a complete sample.
 * @param[in,out] law    The law.
 * @param[in]     y      GL_P outputs.
 * @param[in]     r      GL_Q references (NULL when GL_Q is 0).
 * @param[in]     s      GL_CAN_EXTRA external scheduling signals (NULL when there are none).
 * @param[out]    u      GL_M commands.
 * @param[out]    status The command frames' status byte (GL_CAN_STATUS_* bits).
 * @return The saturation mask of the command frames (bit j: input j clamped).
 */
uint32_t gl_can_law_step(gl_can_law_t *law, const float *y, const float *r, const float *s, float *u,
                         uint8_t *status);

#endif /* GAINLINK_GL_CAN_LAW_H */
