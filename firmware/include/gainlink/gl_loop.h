/**
 * @file gl_loop.h
 * @brief gainlink control loop: the law of docs/design.md in float32, double-buffered gains, watchdog.
 *
 * The law (docs/design.md, "The control law"; predictor form, the current-estimator form is folded into the
 * same step, see below). Samples y, references r, limits and commands are absolute; the estimate xh is a deviation
 * from the operating point (u_op, y_op), all zero for a plant specified about the origin:
 * @code
 *   dy = y - y_op
 *   v  = u_op - K xh - Ki z                (current form: - K xc, xc = xh + M (dy - Cd xh))
 *   u  = clamp(v, u_min, u_max)
 *   z += Ts (r - Ci y)            [+ Kaw (u - v) for back-calculation; skipped on saturation for clamp]
 *   du = u - u_op
 *   xh = Ad xh + Bd du + L (dy - Cd xh - Dd du)     (always fed the saturated u)
 * @endcode
 * The library evaluates it as
 * @code
 *   dy = y - y_op
 *   v  = u_op + dv,  dv = -Kx xh - Ky dy - Ki z    Kx = K (I - M Cd), Ky = K M  (predictor: Kx = K, no Ky)
 *   du = clamp(v, u_min, u_max) - u_op
 *   xh = F xh + G du + L dy          F = Ad - L Cd,  G = Bd - L Dd (current: L = Ad M, Dd = 0)
 * @endcode
 * The offsets are subtracted from the samples before any gain multiplies them, and the feedback sum is
 * formed in deviations before u_op is added once: float32 rounding then scales with the deviations, not
 * with the (possibly large) operating point, and no large constants are formed that would cancel.
 * with F, G, Kx, Ky derived in double precision from the artifact's matrices each time a gain set
 * is accepted (gl_loop_init() or a staged update), so the per-sample step is only multiply-adds.
 * Every multiply-add is an explicit fused `fmaf`, so a host (x86-64, SSE) build and the Cortex-M4F
 * build (`vfma.f32`) give bit-identical results; both are compiled with `-ffp-contract=off` (docs/design.md,
 * "How the C is proved to be the design").
 *
 * Dimensions and structure (n, m, p, q, observer form, anti-windup mode) are compile-time macros from
 * the generated header `gl_gains.h` (`gainlink export ARTIFACT --out DIR`); the numbers are
 * run-time data (::gl_gains_t) and may be replaced while running (see "Gain updates"). The export also
 * writes `gl_step.h`, the step fully unrolled for these dimensions (CMake option GL_STEP_UNROLLED, on by
 * default; it loads coefficients with `vldmia` on the Cortex-M4F). It performs the same operations in the
 * same order as the library's generic loops (GL_STEP_UNROLLED=OFF), so both give bit-identical results.
 *
 * @par Building
 * This is the `lq_float32` law of gl_law.h, which every main, node and binding calls (firmware/CMakeLists.txt and
 * cmake/law.cmake build it as `gainlink_loop` when the export names it, or with `GL_LAW=lq_float32`).
 *
 * @par Gain updates (double-buffered)
 * A gain set is a whole ::gl_gains_t. To change gains at run time (e.g. one parameter over MAVLink):
 * @code
 *   static gl_gains_t staged;                    // caller-owned, e.g. a copy of gl_gains_default
 *   staged = gl_gains_default;
 *   staged.K[0][2] = 1.5f;                       // edit any numbers
 *   staged.crc32 = gl_gains_crc32(&staged);      // seal it (or receive it sealed from the sender)
 *   gl_status_t st = gl_loop_stage(&loop, &staged);   // checks; derives into the inactive bank
 *   // st == GL_OK: the new set becomes active at the start of the next gl_loop_step()
 *   // st <  0   : rejected whole (GL_ERR_DIMS, GL_ERR_NANINF, GL_ERR_CRC, GL_ERR_RANGE, GL_ERR_BUSY);
 *   //             the running set is untouched.
 * @endcode
 * gl_loop_stage() checks, in this order: dimensions and structure against the compiled ones
 * (GL_ERR_DIMS), CRC-32 of the payload (GL_ERR_CRC), finiteness of every number and Ts > 0
 * (GL_ERR_NANINF), u_min <= u_max (GL_ERR_RANGE), then derives F, G, Kx, Ky and checks them finite.
 * The swap happens inside gl_loop_step() before the sample is processed, so a step always runs on one
 * complete set. gl_loop_active_crc32() tells which set is running. gl_loop_stage() may be called from a
 * lower-priority context than gl_loop_step(); only one update can be pending (else GL_ERR_BUSY).
 *
 * @par Faults and watchdog
 * A non-finite y or r leaves xh and z untouched, returns the safe command (u_op clamped into
 * [u_min, u_max]) and GL_ERR_NANINF. Call gl_loop_idle() in a period with no new measurement: it holds
 * the last command, and after `watchdog_periods` consecutive idle periods returns the safe command and
 * GL_ERR_WATCHDOG until the next gl_loop_step().
 */
#ifndef GAINLINK_GL_LOOP_H
#define GAINLINK_GL_LOOP_H

#include <stddef.h>
#include <stdint.h>

#include "gl_artifact.h" /* gl_artifact_name, gl_artifact_sha256 */
#include "gl_status.h" /* gl_status_t */
#include "gl_gains.h" /* generated: GL_N, GL_M, GL_P, GL_Q, GL_OBSERVER_FORM, GL_ANTI_WINDUP, ... */

#ifdef __cplusplus
extern "C" {
#endif

/** Observer forms (values of GL_OBSERVER_FORM and gl_gains_t::observer_form). */
#define GL_FORM_PREDICTOR 0
#define GL_FORM_CURRENT 1

/** Anti-windup modes (values of GL_ANTI_WINDUP and gl_gains_t::anti_windup). */
#define GL_AW_NONE 0
#define GL_AW_CLAMP 1
#define GL_AW_BACKCALC 2

/** Array length used for integrator-sized arrays (C has no zero-length arrays; unused when GL_Q == 0). */
#define GL_QA ((GL_Q) > 0 ? (GL_Q) : 1)

_Static_assert(GL_N >= 1 && GL_N <= 64, "GL_N out of range");
_Static_assert(GL_M >= 1 && GL_M <= 16, "GL_M out of range");
_Static_assert(GL_P >= 1 && GL_P <= 16, "GL_P out of range");
_Static_assert(GL_Q >= 0 && GL_Q <= 16, "GL_Q out of range");
_Static_assert(GL_OBSERVER_FORM == GL_FORM_PREDICTOR || GL_OBSERVER_FORM == GL_FORM_CURRENT, "bad observer form");
_Static_assert(GL_ANTI_WINDUP == GL_AW_NONE || GL_ANTI_WINDUP == GL_AW_CLAMP || GL_ANTI_WINDUP == GL_AW_BACKCALC,
               "bad anti-windup mode");


/* gl_gains_t, one complete gain set (float32; may live in flash), is generated from the field table
 * gainlink.shipping.gains_layout into the export folder with gl_gains.h, so that the C struct, the Python binding and the
 * packers cannot drift apart. */
#include "gl_gains_layout.h"

/** Coefficients per command row of the stream: u_op, Kx (n), Ky (p, current form), Ki (q), u_min, u_max. */
#define GL_VROW (1 + GL_N + ((GL_OBSERVER_FORM) == GL_FORM_CURRENT ? GL_P : 0) + GL_Q + 2)
/** Coefficients per integrator row of the stream: -Ci (p), Ts, Kaw (m, back-calculation only). */
#define GL_ZROW (GL_P + 1 + ((GL_ANTI_WINDUP) == GL_AW_BACKCALC ? GL_M : 0))
/** Coefficients per estimate row of the stream: F (n), G (m), L (p). */
#define GL_XROW (GL_N + GL_M + GL_P)
/** Length of the coefficient stream the step consumes. */
#define GL_STREAM_LEN (GL_P + GL_M * GL_VROW + GL_Q * GL_ZROW + GL_N * GL_XROW)
/** Stream storage, rounded up to whole 16-float chunks (the Cortex-M step loads up to 16 at a time). */
#define GL_STREAM_ALLOC ((((GL_STREAM_LEN) + 15) / 16) * 16)

/**
 * @brief Derived coefficients the step runs on (one bank of the double buffer).
 *
 * `w` holds every coefficient in the exact order gl_loop_step() consumes them, so the step reads
 * it front to back (on the Cortex-M4F up to 16 at a time with `vldmia`):
 * @code
 *   y_op[0..p)
 *   for i < m:  u_op[i]  -Kx[i][0..n)  -Ky[i][0..p) (current form)  -Ki[i][0..q)  u_min[i]  u_max[i]
 *   for j < q:  -Ci[j][0..p)  Ts  Kaw[j][0..m) (back-calculation)
 *   for i < n:  F[i][0..n)  G[i][0..m)  L[i][0..p)
 * @endcode
 */
typedef struct gl_coeffs {
    float w[GL_STREAM_ALLOC]; /**< The coefficient stream (zero padded). */
    float u_safe[GL_M];       /**< The safe command: u_op clamped into the limits. */
    float xh0[GL_N];          /**< Reset estimate. */
    float z0[GL_QA];          /**< Reset integrator. */
    uint32_t crc32;           /**< Checksum of the gain set these were derived from. */
} gl_coeffs_t;

/** @brief Loop instance: caller-owned (static storage), no allocation. Fields are read-only for callers. */
typedef struct gl_loop {
    gl_coeffs_t bank[2];              /**< Double buffer of coefficients. */
    const gl_coeffs_t *active;        /**< The bank gl_loop_step() runs on. */
    volatile uint32_t pending;        /**< 1 when the inactive bank holds an accepted, not yet applied set. */
    float xh[GL_N];                   /**< State estimate. */
    float z[GL_QA];                   /**< Integrator state. */
    float u[GL_M];                    /**< Last command returned. */
    uint32_t sat_mask;                /**< Bit k set when input k saturated on the last step. */
    uint32_t missed;                  /**< Consecutive gl_loop_idle() periods since the last step. */
    uint32_t watchdog_periods;        /**< Idle periods before the safe command. */
    uint32_t faults;                  /**< Count of refused (non-finite) samples. */
    uint32_t swaps;                   /**< Count of applied gain updates. */
} gl_loop_t;

/** The artifact's gain set, generated by `gainlink export` (gl_gains.c). */
extern const gl_gains_t gl_gains_default;

/**
 * @brief Initialise a loop with a gain set and reset its state.
 * @param[out] loop              Loop instance.
 * @param[in]  gains             Gain set (checked as by gl_loop_stage()).
 * @param[in]  watchdog_periods  Idle periods tolerated before the safe command (>= 1).
 * @return GL_OK, or GL_ERR_NULL / GL_ERR_DIMS / GL_ERR_CRC / GL_ERR_NANINF / GL_ERR_RANGE.
 */
gl_status_t gl_loop_init(gl_loop_t *loop, const gl_gains_t *gains, uint32_t watchdog_periods);

/**
 * @brief Copy a loop instance whole (state, both banks, a staged set), e.g. to restore a snapshot.
 *
 * A plain struct copy would leave the copy running on the original's bank (gl_loop_t::active points into
 * gl_loop_t::bank); this one runs on its own. Not for a loop another context may stage into meanwhile.
 * @param[out] dst  Copy.
 * @param[in]  src  Loop initialised by gl_loop_init() (distinct from dst).
 * @return GL_OK, or GL_ERR_NULL (dst untouched).
 */
gl_status_t gl_loop_copy(gl_loop_t *dst, const gl_loop_t *src);

/**
 * @brief Put xh and z back to the active set's xh0, z0; clear the watchdog; the last command becomes the safe one.
 * @param[in,out] loop  Loop instance.
 * @return GL_OK or GL_ERR_NULL.
 */
gl_status_t gl_loop_reset(gl_loop_t *loop);

/**
 * @brief One sample of the control law.
 * @param[in,out] loop  Loop instance (a pending gain set is applied first).
 * @param[in]  y        Absolute measurement, GL_P values.
 * @param[in]  r        Absolute reference of the tracked outputs, GL_Q values (may be NULL when GL_Q == 0).
 * @param[out] u        Command, GL_M values.
 * @return GL_OK, GL_SATURATED (see loop->sat_mask), GL_ERR_NANINF (state untouched, u = safe command)
 *         or GL_ERR_NULL.
 */
gl_status_t gl_loop_step(gl_loop_t *loop, const float *y, const float *r, float *u);

/**
 * @brief A period without a new measurement: hold the last command, or the safe one once the watchdog expired.
 * @param[in,out] loop  Loop instance.
 * @param[out]    u     Command, GL_M values.
 * @return GL_OK while holding, GL_ERR_WATCHDOG once `watchdog_periods` idle periods have passed, GL_ERR_NULL.
 */
gl_status_t gl_loop_idle(gl_loop_t *loop, float *u);

/**
 * @brief Check a gain set and stage it in the inactive bank; applied at the next gl_loop_step().
 * @param[in,out] loop   Loop instance.
 * @param[in]     gains  Candidate set (its crc32 must match gl_gains_crc32()).
 * @return GL_OK (staged), or an error and nothing changed (see "Gain updates").
 */
gl_status_t gl_loop_stage(gl_loop_t *loop, const gl_gains_t *gains);

/**
 * @brief Check a gain set without staging it (same checks as gl_loop_stage()).
 * @param[in] gains  Candidate set.
 * @return GL_OK or the first failing check's error.
 */
gl_status_t gl_gains_check(const gl_gains_t *gains);

/**
 * @brief CRC-32 (IEEE 802.3, reflected, as zlib.crc32) of a gain set's payload (all fields but crc32).
 * @param[in] gains  Gain set.
 * @return The checksum (0 if gains is NULL).
 */
uint32_t gl_gains_crc32(const gl_gains_t *gains);

/**
 * @brief Checksum of the gain set currently running.
 * @param[in] loop  Loop instance.
 * @return Its crc32 (0 if loop is NULL).
 */
uint32_t gl_loop_active_crc32(const gl_loop_t *loop);

#ifdef __cplusplus
}
#endif

#endif /* GAINLINK_GL_LOOP_H */
