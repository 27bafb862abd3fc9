/**
 * @file gl_mav_law.h
 * @brief The law the MAVLink node runs, chosen when it is compiled from what the export holds:
 *        - a fixed-point export (gl_fixed_gains.c, `[implementation] numeric = "q31" | "q15"`; apps/mavlink/
 *          CMakeLists.txt then defines GL_MAV_LAW_FIXED=1, for the host app and the Cortex-M image alike): the
 *          integer loop (gl_fixed.h) the artifact certifies, on the integers of its parameter table (gl_mav_fxset.h);
 *        - a scheduled artifact's export (gl_gains.h with GL_SCHEDULED 1): the scheduled loop (gl_sched.h), its
 *          sigma read from the measured output the schedule names or from the external scheduling signals, which
 *          the HIL sample then carries after its references (data = y, r, s: GL_MAV_EXTRA values); its parameter
 *          table (gl_mav_schedparams.c) holds every point's gains, staged and committed through GL_HASH (the CRC-32
 *          of its tables) as one set;
 *        - otherwise the float32 loop (gl_loop.h), as it always was (the node calls it directly: nothing here).
 *
 * The integer law takes the same float samples and returns float commands; its HIL answer carries the float
 * law's flags (fault, watchdog, reset, saturation bits 8+k) and two of its own: GL_MAV_FLAG_CLIPPED (a sample or
 * reference outside its declared range, clipped) and GL_MAV_FLAG_OVERFLOW (its second-line saturation fired: the
 * certificate says it never does in range). Its watchdog is the float loop's: after `watchdog_periods`
 * consecutive idle periods the safe command (u_op clamped into the limits) until the next sample. No allocation.
 *
 * The scheduled law sets the float law's flags and its sigma flags: GL_MAV_FLAG_SIGMA_HELD (sigma was not finite,
 * the last valid one was used), GL_MAV_FLAG_SIGMA_CLIPPED (clipped to [S1, SN]) and GL_MAV_FLAG_SIGMA_RATE (its
 * change was rate-limited). Its watchdog is the float loop's too; its safe command is u_op at the held sigma,
 * clamped (what gl_sched_step() answers a refused sample), and it leaves the law's state untouched.
 *
 * GL_MAV_LAW_ID is what the HEARTBEAT's custom_mode says (0 float32, 31 q31, 15 q15: the coefficient word's
 * fraction bits; 256 the scheduled float32 law), GL_MAV_LAW_NAME what the ready line names (`law=`; the float32
 * line names none).
 */
#ifndef GL_MAV_LAW_H
#define GL_MAV_LAW_H

#include <stdint.h>

#include "gl_gains.h" /* generated: says whether the law is scheduled */

/** HIL_ACTUATOR_CONTROLS flags (gl_mav_node.h) the laws set. */
#define GL_MAV_FLAG_FAULT 0x1u
#define GL_MAV_FLAG_WATCHDOG 0x2u
#define GL_MAV_FLAG_RESET 0x4u
#define GL_MAV_FLAG_CLIPPED 0x8u  /**< fixed point: a sample or reference was clipped to its declared range */
#define GL_MAV_FLAG_OVERFLOW 0x10u /**< fixed point: the second-line saturation fired */
#define GL_MAV_FLAG_SIGMA_HELD 0x20u    /**< scheduled: sigma was not finite, the last valid one was used */
#define GL_MAV_FLAG_SIGMA_CLIPPED 0x40u /**< scheduled: sigma was clipped to the envelope [S1, SN] */
#define GL_MAV_FLAG_SIGMA_RATE 0x80u    /**< scheduled: sigma's change was rate-limited */
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

#elif defined(GL_SCHEDULED) && GL_SCHEDULED
#include "gainlink/gl_sched.h"
#define GL_MAV_LAW_SCHED 1
#define GL_MAV_LAW_NAME "scheduled-float32"
#define GL_MAV_LAW_ID 256u
/** Values a HIL sample carries after the references: the external scheduling signals (GL_E). */
#define GL_MAV_EXTRA GL_E
/** The node's status type and codes (gl_sched_status_t has gl_status_t's values; gl_loop.h is not built). */
typedef gl_sched_status_t gl_status_t;
#define GL_OK GL_SCHED_OK
#define GL_ERR_NULL GL_SCHED_ERR_NULL
#define GL_ERR_NANINF GL_SCHED_ERR_NANINF
#define GL_WATCHDOG_PERIODS_DEFAULT 10u /**< as the unscheduled export's (gainlink.shipping.codegen) */

/** The scheduled law and its watchdog. */
typedef struct gl_mav_sched {
    gl_sched_t loop;           /**< The scheduled loop. */
    uint32_t missed;           /**< Consecutive idle periods since the last sample. */
    uint32_t watchdog_periods; /**< Idle periods before the safe command. */
} gl_mav_sched_t;

/**
 * @brief Start the law on tables `t`.
 * @param[out] law The law. @param[in] t The tables (kept by reference: must outlive the law; a committed set replaces
 * them in place between two steps, then gl_mav_sched_retable()).
 * @param[in] watchdog_periods Idle periods before the safe command.
 * @return GL_SCHED_OK, or gl_sched_init()'s refusal of the tables.
 */
gl_status_t gl_mav_sched_init(gl_mav_sched_t *law, const gl_sched_tables_t *t, uint32_t watchdog_periods);

/** @brief Its tables changed in place (a commit): interpolate them anew at the next step, state kept. @param law */
void gl_mav_sched_retable(gl_mav_sched_t *law);

/**
 * @brief One step on a sample. @param[in,out] law The law. @param[in] y GL_P outputs.
 * @param[in] r GL_Q references. @param[in] s GL_E external scheduling signals (NULL when GL_E is 0).
 * @param[out] u GL_M commands. @return The HIL flags (GL_MAV_FLAG_* and the saturation bits).
 */
uint64_t gl_mav_sched_step(gl_mav_sched_t *law, const float *y, const float *r, const float *s, float *u);

/** @brief Back to the initial state: u is the start command. @param[in,out] law @param[out] u @return flags. */
uint64_t gl_mav_sched_reset(gl_mav_sched_t *law, float *u);

/** @brief A period without a sample. @param[in,out] law @param[out] u held or safe command. @return flags. */
uint64_t gl_mav_sched_idle(gl_mav_sched_t *law, float *u);

#else
#define GL_MAV_LAW_NAME "float32"
#define GL_MAV_LAW_ID 0u
#endif

#ifndef GL_MAV_EXTRA
#define GL_MAV_EXTRA 0 /**< Values after the references in a HIL sample: none but for a scheduled law's. */
#endif

#endif /* GL_MAV_LAW_H */
