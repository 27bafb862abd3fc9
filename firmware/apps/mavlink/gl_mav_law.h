/**
 * @file gl_mav_law.h
 * @brief The law the MAVLink node runs, chosen when it is compiled from what the export holds:
 *        - a fixed-point export (gl_fixed_gains.c, `[implementation] numeric = "q31" | "q15"`; apps/mavlink/
 *          CMakeLists.txt then defines GL_MAV_LAW_FIXED=1 on the host): the integer loop (gl_fixed.h) the artifact
 *          certifies, on the integers of its parameter table (gl_mav_fixed_params.h);
 *        - otherwise the float32 loop (gl_loop.h), as it always was (the node calls it directly: nothing here).
 *
 * The integer law takes the same float samples and returns float commands; its HIL answer carries the float
 * law's flags (fault, watchdog, reset, saturation bits 8+k) and two of its own: GL_MAV_FLAG_CLIPPED (a sample or
 * reference outside its declared range, clipped) and GL_MAV_FLAG_OVERFLOW (its second-line saturation fired: the
 * certificate says it never does in range). Its watchdog is the float loop's: after `watchdog_periods`
 * consecutive idle periods the safe command (u_op clamped into the limits) until the next sample. No allocation.
 *
 * GL_MAV_LAW_ID is what the HEARTBEAT's custom_mode says (0 float32, 31 q31, 15 q15: the coefficient word's
 * fraction bits), GL_MAV_LAW_NAME what the ready line names (`law=`; the float32 line names none).
 */
#ifndef GL_MAV_LAW_H
#define GL_MAV_LAW_H

#include <stdint.h>

/** HIL_ACTUATOR_CONTROLS flags (gl_mav_node.h) the laws set. */
#define GL_MAV_FLAG_FAULT 0x1u
#define GL_MAV_FLAG_WATCHDOG 0x2u
#define GL_MAV_FLAG_RESET 0x4u
#define GL_MAV_FLAG_CLIPPED 0x8u  /**< fixed point: a sample or reference was clipped to its declared range */
#define GL_MAV_FLAG_OVERFLOW 0x10u /**< fixed point: the second-line saturation fired */
#define GL_MAV_SAT_SHIFT 8

#if defined(GL_MAV_LAW_FIXED) && GL_MAV_LAW_FIXED
#include "gainlink/gl_fixed.h"
#if GL_NUMERIC_Q31
#define GL_MAV_LAW_NAME "q31"
#define GL_MAV_LAW_ID 31u
#else
#define GL_MAV_LAW_NAME "q15"
#define GL_MAV_LAW_ID 15u
#endif

/** The integer law and its watchdog. */
typedef struct gl_mav_fixed {
    gl_fixed_loop_t loop;      /**< The integer loop. */
    uint32_t missed;           /**< Consecutive idle periods since the last sample. */
    uint32_t watchdog_periods; /**< Idle periods before the safe command. */
} gl_mav_fixed_t;

/**
 * @brief Start the law on gain set `g`.
 * @param[out] law The law. @param[in] g The integers (kept by reference: must outlive the law).
 * @param[in] watchdog_periods Idle periods before the safe command.
 * @return 0, or -1 when an argument is NULL.
 */
int gl_mav_fixed_init(gl_mav_fixed_t *law, const gl_fixed_gains_t *g, uint32_t watchdog_periods);

/**
 * @brief One step on a sample. @param[in,out] law The law. @param[in] y GL_FX_P outputs.
 * @param[in] r GL_FX_Q references (NULL when there are none). @param[out] u GL_FX_M commands.
 * @return The HIL flags (GL_MAV_FLAG_* and the saturation bits).
 */
uint64_t gl_mav_fixed_step(gl_mav_fixed_t *law, const float *y, const float *r, float *u);

/** @brief Back to the initial state: u is the safe command. @param[in,out] law @param[out] u @return flags. */
uint64_t gl_mav_fixed_reset(gl_mav_fixed_t *law, float *u);

/** @brief A period without a sample. @param[in,out] law @param[out] u held or safe command. @return flags. */
uint64_t gl_mav_fixed_idle(gl_mav_fixed_t *law, float *u);

#else
#define GL_MAV_LAW_NAME "float32"
#define GL_MAV_LAW_ID 0u
#endif

#endif /* GL_MAV_LAW_H */
