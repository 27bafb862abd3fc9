/**
 * @file gl_can_law.h
 * @brief The law the CAN node runs, chosen when it is compiled: the float32 loop (gl_loop.h) or, when the
 *        export holds the artifact's fixed-point law (gl_fixed_gains.c, `[implementation] numeric = "q31" | "q15"`),
 *        the integer loop (gl_fixed.h) the artifact certifies.
 *
 * apps/can/CMakeLists.txt defines GL_CAN_LAW_FIXED=1 for a fixed-point export (host builds). Both laws take
 * the same float samples and return float commands; what they report becomes the command frames' status byte
 * and saturation mask: a refused (non-finite) sample sets GL_CAN_STATUS_FAULT, a clamped input its `sat` bit;
 * the fixed law also sets GL_CAN_STATUS_CLIPPED (a sample or reference outside its declared range, clipped) and
 * GL_CAN_STATUS_OVERFLOW (its second-line saturation fired: the certificate says it never does in range).
 * No allocation: the law lives in the node's static storage.
 */
#ifndef GAINLINK_GL_CAN_LAW_H
#define GAINLINK_GL_CAN_LAW_H

#include <stdint.h>

#include "gainlink/gl_loop.h"

#if defined(GL_CAN_LAW_FIXED) && GL_CAN_LAW_FIXED
#include "gainlink/gl_fixed.h"
/** The law's state: the integer loop. */
typedef gl_fixed_loop_t gl_can_law_t;
#if GL_NUMERIC_Q31
#define GL_CAN_LAW_NAME "q31" /**< What the ready line names (law=). */
#else
#define GL_CAN_LAW_NAME "q15"
#endif
#else
/** The law's state: the float32 loop. */
typedef gl_loop_t gl_can_law_t;
#define GL_CAN_LAW_NAME "float32"
#endif

/**
 * @brief Start the law on the compiled gains.
 * @param[out] law              The law.
 * @param[in]  watchdog_periods Idle periods before the float loop's safe command (unused by the fixed law).
 * @return GL_OK, or the float loop's refusal of the compiled gains (GL_ERR_NULL for the fixed law's).
 */
gl_status_t gl_can_law_init(gl_can_law_t *law, uint32_t watchdog_periods);

/**
 * @brief One step on a complete sample.
 * @param[in,out] law    The law.
 * @param[in]     y      GL_P outputs.
 * @param[in]     r      GL_Q references (NULL when GL_Q is 0).
 * @param[out]    u      GL_M commands.
 * @param[out]    status The command frames' status byte (GL_CAN_STATUS_* bits).
 * @return The saturation mask of the command frames (bit j: input j clamped).
 */
uint32_t gl_can_law_step(gl_can_law_t *law, const float *y, const float *r, float *u, uint8_t *status);

#endif /* GAINLINK_GL_CAN_LAW_H */
