/**
 * @file gl_sched.h
 * @brief gainlink scheduled loop: the gain-scheduled law of docs/design.md ("Scheduled law") in float32.
 *
 * The law is the velocity form on coefficients interpolated linearly in sigma between the artifact's points
 * S1 < ... < SN (docs/design.md, scheduled law; gainlink.proof.scheduled_reference is its float64 reference and
 * gainlink.proof.scheduled_float32 this file's arithmetic bit for bit). One step, on the absolute measurement y (p),
 * reference r (q) and external scheduling signals s (e):
 * @code
 *   1. y or r not finite: nothing changes; u = clamp(u_op(sigma_held)), GL_SCHED_ERR_NANINF.
 *   2. raw = y[GL_SIGMA_INDEX] (sigma an output) or s[GL_SIGMA_INDEX] (GL_SIGMA_EXTERNAL)
 *      raw not finite:  sigma = sigma_held                                  (flag GL_SIGMA_HELD)
 *      else: c = clip(raw, S1, SN)                                          (flag GL_SIGMA_CLIPPED when c != raw)
 *            not started: sigma_f = c, sigma = c
 *            else: sigma_f = fmaf(alpha, c - sigma_f, sigma_f)              (GL_SIGMA_FILTERED; else sigma_f = c)
 *                  d = sigma_f - sigma_held
 *                  |d| > rate_step: sigma = sigma_held +- rate_step         (GL_SIGMA_RATE_LIMITED; flag GL_SIGMA_RATE)
 *                  else sigma = sigma_f
 *      sigma_held = sigma
 *   3. i with Si <= sigma <= Si+1 (the last interval at SN), lam = (sigma - Si) / (Si+1 - Si)
 *      X = fmaf(lam, X[i+1] - X[i], X[i]) for X in Kx Ky Kz F G Ly
 *   4. first valid step after a reset: y_prev = y, u_prev = clamp(u_op(sigma)), e_prev = 0, delta = 0
 *      dy = y - y_prev
 *      v  = u_prev - (Kx delta + Ky dy + Kz e_prev)          (Ky only in the current form; Kz = Ts Ki)
 *      u  = clamp(v, u_min, u_max)                           (saturation bits in sat_mask)
 *      delta = F delta + G (u - u_prev) + Ly dy              (the observer sees the applied increment)
 *      e_prev = r - Ci y;  y_prev = y;  u_prev = u           (u_prev is the saturated command: anti-windup)
 * @endcode
 * Every sum starts with a product of its first terms and adds the others with one fused multiply-add each
 * (GL_FMA: `vfma.f32` on the Cortex-M4F, `fmaf` on the host, both built with `-ffp-contract=off`), in the order
 * written above, so the host and the Cortex-M4F give the same bits. No allocation; the loop is caller-owned.
 *
 * What the step keeps to cost less changes no bit: X[i] and X[i+1] - X[i] of the interval it is in (computed once
 * per interval entered; the interval is kept while +0 <= lam < 1, or <= 1 on the last), the coefficients of a
 * sigma that stands (kept in c from its second step), and, while sigma moves, each coefficient interpolated where
 * it multiplies, except those the export found equal at every point (GL_SCHED_FIXED_*: fmaf(lam, +0, x) == x for
 * such an x, not -0; the step checks the tables against the masks at init and gl_sched_retable() and
 * interpolates every coefficient when they do not hold). Without a filter and a rate limit, a sigma that moved and
 * lies in the kept interval (then inside the envelope: not clipped) goes straight to the law.
 *
 * The trims u_op only start the law and give its safe command; the law itself holds no trim, and a moving sigma
 * never steps the command (docs/design.md: "no hidden coupling").
 *
 * Dimensions and the shape of sigma are compile-time macros of the generated `gl_gains.h` of a scheduled artifact
 * (`gainlink export`): GL_SCHEDULED, GL_N, GL_M, GL_P, GL_Q, GL_NPTS, GL_E, GL_OBSERVER_FORM, GL_SIGMA_EXTERNAL,
 * GL_SIGMA_INDEX, GL_SIGMA_FILTERED, GL_SIGMA_RATE_LIMITED. The per-point tables are the generated
 * `gl_sched_default` (gl_sched_gains.c). This is the `scheduled_float32` law of gl_law.h, which every main, node and
 * binding calls (cmake/law.cmake builds it when the export names it).
 */
#ifndef GAINLINK_GL_SCHED_H
#define GAINLINK_GL_SCHED_H

#include <stdint.h>

#include "gl_artifact.h" /* gl_artifact_name, gl_artifact_sha256 */
#include "gl_gains.h" /* generated for a scheduled artifact */

#ifdef __cplusplus
extern "C" {
#endif

#if !defined(GL_SCHEDULED) || GL_SCHEDULED != 1
#error "gl_sched.h needs the gl_gains.h of a scheduled artifact (GL_SCHEDULED 1)"
#endif

_Static_assert(GL_N >= 1 && GL_N <= 64, "GL_N out of range");
_Static_assert(GL_M >= 1 && GL_M <= 16, "GL_M out of range");
_Static_assert(GL_P >= 1 && GL_P <= 16, "GL_P out of range");
_Static_assert(GL_Q == GL_M, "a scheduled law integrates every input (q = m)");
_Static_assert(GL_NPTS >= 2 && GL_NPTS <= 64, "GL_NPTS out of range");
_Static_assert(GL_E >= 0 && GL_E <= 16, "GL_E out of range");
_Static_assert(GL_SIGMA_INDEX >= 0 && GL_SIGMA_INDEX < (GL_SIGMA_EXTERNAL ? GL_E : GL_P), "bad sigma index");

/** Current-estimator form (Ky is used); predictor form has Ky = 0 and skips it. */
#define GL_SCHED_FORM_CURRENT 1
/* Bit k (k < 32) of GL_SCHED_FIXED_<X>: coefficient k of X is the same float32 at every point (and not -0), so the
 * step does not interpolate it (gl_gains.h of `gainlink export` defines them; checked against the tables at init). */
#ifndef GL_SCHED_FIXED_KX
#define GL_SCHED_FIXED_KX 0u
#endif
#ifndef GL_SCHED_FIXED_KY
#define GL_SCHED_FIXED_KY 0u
#endif
#ifndef GL_SCHED_FIXED_KZ
#define GL_SCHED_FIXED_KZ 0u
#endif
#ifndef GL_SCHED_FIXED_F
#define GL_SCHED_FIXED_F 0u
#endif
#ifndef GL_SCHED_FIXED_G
#define GL_SCHED_FIXED_G 0u
#endif
#ifndef GL_SCHED_FIXED_LY
#define GL_SCHED_FIXED_LY 0u
#endif

/** Array length for external-signal arrays (C has no zero-length arrays; unused when GL_E == 0). */
#define GL_EA ((GL_E) > 0 ? (GL_E) : 1)

/** Sigma flags of a step (gl_sched_t::sigma_flags). */
#define GL_SIGMA_HELD 1u    /**< The raw sigma was not finite: the last valid one was used. */
#define GL_SIGMA_CLIPPED 2u /**< The raw sigma was outside [S1, SN] and was clipped. */
#define GL_SIGMA_RATE 4u    /**< Sigma's change was limited to rate_step. */

/** Status codes (the same values as gl_status_t of gl_loop.h). */
typedef enum gl_sched_status {
    GL_SCHED_OK = 0,           /**< Step done, no input saturated / call succeeded. */
    GL_SCHED_SATURATED = 1,    /**< Step done, at least one input was clamped (see gl_sched_t::sat_mask). */
    GL_SCHED_ERR_NULL = -1,    /**< A required pointer was NULL. */
    GL_SCHED_ERR_NANINF = -2,  /**< Non-finite measurement/reference (step) or table entry (init). */
    GL_SCHED_ERR_DIMS = -4,    /**< Tables that break the compiled GL_SCHED_FIXED_* masks (gl_sched_check()). */
    GL_SCHED_ERR_RANGE = -5    /**< Tables out of range: points not increasing, u_min > u_max, bad alpha/rate. */
} gl_sched_status_t;

/** @brief The per-point tables of a scheduled artifact (float32, row-major per point; may live in flash). */
typedef struct gl_sched_tables {
    float S[GL_NPTS];                /**< The points S1 < ... < SN. */
    float Kx[GL_NPTS][GL_M * GL_N];  /**< Estimate feedback per point. */
    float Ky[GL_NPTS][GL_M * GL_P];  /**< Measurement feedback per point (current form; zero in predictor). */
    float Kz[GL_NPTS][GL_M * GL_Q];  /**< Integrator increment gain Ts Ki per point. */
    float F[GL_NPTS][GL_N * GL_N];   /**< Observer transition per point. */
    float G[GL_NPTS][GL_N * GL_M];   /**< Observer input gain per point. */
    float Ly[GL_NPTS][GL_N * GL_P];  /**< Observer measurement gain per point. */
    float u_op[GL_NPTS][GL_M];       /**< Trim per point (start and safe command only). */
    float u_min[GL_M];               /**< Lower command limits. */
    float u_max[GL_M];               /**< Upper command limits. */
    float Ci[GL_Q * GL_P];           /**< Tracked-output selection (e = r - Ci y). */
    float alpha;                     /**< Sigma filter gain per step, 1 - exp(-Ts / tau) (1: no filter). */
    float rate_step;                 /**< Largest change of sigma per step, Ts rate_max (unused without limit). */
} gl_sched_tables_t;

/** @brief Coefficients interpolated at one sigma (what the step multiplies). */
typedef struct gl_sched_coeffs {
    float Kx[GL_M * GL_N];
    float Ky[GL_M * GL_P];
    float Kz[GL_M * GL_Q];
    float F[GL_N * GL_N];
    float G[GL_N * GL_M];
    float Ly[GL_N * GL_P];
} gl_sched_coeffs_t;

/** @brief Scheduled loop instance: caller-owned (static storage), no allocation. Fields are read-only for callers. */
typedef struct gl_sched {
    const gl_sched_tables_t *t; /**< The tables it runs on. */
    gl_sched_coeffs_t c;        /**< Coefficients interpolated at c_sigma (kept while sigma stands). */
    gl_sched_coeffs_t x0;       /**< The cached interval's coefficients at its first point, X[i]. */
    gl_sched_coeffs_t d;        /**< And their differences X[i+1] - X[i] (float32, as the law computes them). */
    uint32_t c_sigma;           /**< The bits of the sigma whose coefficients c holds (a NaN's: none). */
    uint32_t c_span;            /**< The cached interval holds sigma when lam's bits are below it (0: none cached). */
    uint32_t c_limit;           /**< c_span when fixed_ok, else 0 (the step interpolates every coefficient). */
    uint32_t c_inner;           /**< 0x3f800000 (lam < 1) when c_limit is not 0, else 0. */
    uint32_t fixed_ok;          /**< 1 when the tables hold the GL_SCHED_FIXED_* masks (checked at init, retable). */
    float c_s0;                 /**< S[i] of the cached interval. */
    float c_width;              /**< S[ci+1] - S[i] of the cached interval. */
    float delta[GL_N];          /**< The estimate's increment xh[k] - xh[k-1]. */
    float u_prev[GL_M];         /**< Last applied (saturated) command. */
    float y_prev[GL_P];         /**< Last valid measurement. */
    float e_prev[GL_Q];         /**< Last tracking error r - Ci y. */
    float sigma;                /**< The held sigma (used by the last valid step). */
    float sigma_f;              /**< Sigma's filter state. */
    uint32_t started;           /**< 0 until the first valid sample after a reset. */
    float u[GL_M];              /**< Last command returned. */
    uint32_t sat_mask;          /**< Bit k set when input k saturated on the last step. */
    uint32_t sigma_flags;       /**< GL_SIGMA_* of the last step (0 on a refused sample). */
    uint32_t faults;            /**< Count of refused (non-finite) samples. */
} gl_sched_t;

/**
 * @brief A gain set of the scheduled law as an upload changes it: the tables, the CRC-32 of their bytes (the MAVLink
 *        table's `GL_HASH`, gl_sched_tables_crc32()) and the compatibility signature of the law they were made for
 *        (GL_LAW_SIGNATURE of gl_law.h: dimensions, points, external signals, the GL_SCHED_FIXED_* masks).
 */
typedef struct gl_sched_set {
    gl_sched_tables_t t; /**< The tables (first: a pointer to the set is one to them). */
    uint32_t crc32;      /**< gl_sched_tables_crc32() of the tables. */
    uint32_t signature;  /**< The law's compatibility signature. */
} gl_sched_set_t;

/** The artifact's tables as a set, generated by `gainlink export` (gl_sched_gains.c). */
extern const gl_sched_set_t gl_sched_default;

/**
 * @brief Check the tables and start a loop on them (reset state).
 * @param[out] loop    Loop instance.
 * @param[in]  tables  Tables (kept by address: must outlive the loop).
 * @return GL_SCHED_OK, GL_SCHED_ERR_NULL, GL_SCHED_ERR_NANINF or GL_SCHED_ERR_RANGE (loop untouched).
 */
gl_sched_status_t gl_sched_init(gl_sched_t *loop, const gl_sched_tables_t *tables);

/**
 * @brief Back to the start: delta = 0, sigma at S1, not started (the next valid sample starts the law there).
 * @param[in,out] loop  Loop instance.
 * @return GL_SCHED_OK or GL_SCHED_ERR_NULL.
 */
gl_sched_status_t gl_sched_reset(gl_sched_t *loop);

/**
 * @brief Forget every coefficient the loop keeps (interpolated, or of its interval): call it after changing the
 *        tables it runs on in place (the next step interpolates from them again). The law's state is untouched.
 * @param[in,out] loop  Loop instance.
 */
void gl_sched_retable(gl_sched_t *loop);

/**
 * @brief One sample of the scheduled law (see the file comment).
 * @param[in,out] loop  Loop instance.
 * @param[in]  y        Absolute measurement, GL_P values.
 * @param[in]  r        Absolute reference of the tracked outputs, GL_Q values.
 * @param[in]  s        External scheduling signals, GL_E values (may be NULL when GL_E == 0).
 * @param[out] u        Command, GL_M values.
 * @return GL_SCHED_OK, GL_SCHED_SATURATED, GL_SCHED_ERR_NANINF (state untouched, u = safe command) or
 *         GL_SCHED_ERR_NULL.
 */
gl_sched_status_t gl_sched_step(gl_sched_t *loop, const float *y, const float *r, const float *s, float *u);

/**
 * @brief Whether tables can run on this build: every number finite, the points increasing, the limits ordered, alpha
 *        and the rate step in range (as gl_sched_init()), and the coefficients the step was compiled not to
 *        interpolate (GL_SCHED_FIXED_*) the same at every point. gl_sched_init() runs tables that break the masks
 *        (interpolating every coefficient); a gain set an upload stages must hold them.
 * @param[in] tables Tables.
 * @return GL_SCHED_OK, GL_SCHED_ERR_NULL, GL_SCHED_ERR_NANINF, GL_SCHED_ERR_RANGE or GL_SCHED_ERR_DIMS.
 */
gl_sched_status_t gl_sched_check(const gl_sched_tables_t *tables);

/**
 * @brief CRC-32 (zlib's) of the tables' bytes: the MAVLink table's `GL_HASH`.
 * @param[in] tables Tables. @return The checksum.
 */
uint32_t gl_sched_tables_crc32(const gl_sched_tables_t *tables);

/**
 * @brief The safe command: u_op at the held sigma, clamped into the limits (what a refused sample gets), without
 *        changing the loop.
 * @param[in] loop Loop instance. @param[out] u GL_M commands.
 */
void gl_sched_safe(const gl_sched_t *loop, float *u);

/** Length of the state vector gl_sched_state() writes: delta, u_prev, y_prev, e_prev, sigma, sigma_f, started. */
#define GL_SCHED_STATE_LEN (GL_N + GL_M + GL_P + GL_Q + 3)

/**
 * @brief The loop's whole state as one vector (what a one-step check resynchronises on).
 * @param[in]  loop  Loop instance.
 * @param[out] out   GL_SCHED_STATE_LEN values: delta (n), u_prev (m), y_prev (p), e_prev (q), sigma, sigma_f,
 *                   started (0 or 1).
 */
void gl_sched_state(const gl_sched_t *loop, float *out);

#ifdef __cplusplus
}
#endif

#endif /* GAINLINK_GL_SCHED_H */
