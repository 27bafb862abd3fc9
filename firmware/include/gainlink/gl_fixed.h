/**
 * @file gl_fixed.h
 * @brief gainlink fixed-point loop: the law of docs/design.md ("Fixed point") on integers, q31 or q15.
 *
 * For cores without an FPU. The integers (coefficient mantissas and shifts, rounding shifts, operating point,
 * limits, safe command, initial state, formats and ranges) are those the design certified, stored in the
 * artifact (`checks.fixed_point.integers`) and rendered by `gainlink export` into `gl_fixed_gains.h` /
 * `gl_fixed_gains.c` as the const ::gl_fixed_set_t `gl_fixed_default`: never recomputed here. A signal in
 * format f is an integer X meaning X 2^-f. The step, in this order (bit for bit the reference model
 * gainlink.proof.fixed_law, whose module docstring is the same list):
 * @code
 *   0. a y or r not finite: U = U_SAFE, GL_FX_FAULT, state untouched
 *   1. Y = quantise(clip(y, y_min, y_max), f_y), ties up, exact; clip bit when clipped; same for R
 *   2. dY = sat_Ws(Y - YOP)
 *   3. V[i]  = sat_32(UOP_V[i] + rshift_round(KX.XH + KY.dY + KZ.Z, shift_v[i]))
 *   4. Uv[i] = clamp(V[i], LO_V[i], HI_V[i]);   saturated bit i when Uv[i] != V[i]
 *   5. U[i]  = rshift_round(Uv[i], shift_u[i]); dU[i] = sat_Wc(U[i] - UOP_U[i])
 *   6. Z'[j] = sat_32(Z[j] + rshift_round(TR.R + TY.Y + KAW.(Uv - V), shift_z[j]))   (clamp: Z' = Z if saturated)
 *   7. XH'[i] = sat_32(rshift_round(F.XH + G.dU + LY.dY, shift_x[i]))
 *   8. commit XH, Z; return U (and u = U 2^-f_u as float)
 * @endcode
 * `C.S` is `sum_k (C[k] S[k]) << E[k]` over the row's non-zero coefficients, each product exact in an int64
 * accumulator; `rshift_round(a, s)` is `(a + 2^(s-1)) >> s` (s > 0), `a` (s = 0), `a << -s` (s < 0);
 * `sat_W` clips to W bits and sets a bit of GL_FX_OVERFLOW (the second line: the certificate proves it never
 * fires for inputs in the declared ranges). The step is integer arithmetic only, the quantisation of the
 * samples included (a float's bits, scaled by its format); the one float operation is the conversion of the
 * command word to the returned float command. No malloc, no libm.
 *
 * Words (q31 / q15): coefficients, samples and commands 32 / 16 bits (::gl_fx_coef_t, ::gl_fx_word_t); estimate,
 * integrators and the unsaturated command 32 bits; accumulators 64 bits.
 *
 * @par Building
 * These are the `lq_q31` and `lq_q15` laws of gl_law.h, which every main, node and binding calls (cmake/law.cmake
 * builds them when the export names one: `gainlink_loop`, with the generated row sums of gl_fixed_step.h,
 * GL_FX_UNROLLED; and `gainlink_loop_generic`, the table-driven loop the MAVLink node runs, bit for bit the same).
 */
#ifndef GAINLINK_GL_FIXED_H
#define GAINLINK_GL_FIXED_H

#include <stdint.h>

#include "gl_fixed_gains.h" /* generated: GL_NUMERIC_Q31 or GL_NUMERIC_Q15, GL_FX_N/M/P/Q, GL_FX_TERMS, ... */

#if GL_NUMERIC_Q31
typedef int32_t gl_fx_coef_t; /**< A coefficient mantissa. */
typedef int32_t gl_fx_word_t; /**< A sample or command word. */
#define GL_FX_WORD_BITS 32
#elif GL_NUMERIC_Q15
typedef int16_t gl_fx_coef_t;
typedef int16_t gl_fx_word_t;
#define GL_FX_WORD_BITS 16
#else
#error "gl_fixed_gains.h defines neither GL_NUMERIC_Q31 nor GL_NUMERIC_Q15"
#endif

/** Rows of sums of products: the m commands, then the q integrators, then the n estimates. */
#define GL_FX_ROWS (GL_FX_M + GL_FX_Q + GL_FX_N)

/** Offsets of the signals the sums read, in ::gl_fixed_loop_t::sig. */
#define GL_FX_SIG_XH 0
#define GL_FX_SIG_DY (GL_FX_SIG_XH + GL_FX_N)
#define GL_FX_SIG_Z (GL_FX_SIG_DY + GL_FX_P)
#define GL_FX_SIG_DU (GL_FX_SIG_Z + GL_FX_Q)
#define GL_FX_SIG_R (GL_FX_SIG_DU + GL_FX_M)
#define GL_FX_SIG_Y (GL_FX_SIG_R + GL_FX_Q)
#define GL_FX_SIG_W (GL_FX_SIG_Y + GL_FX_P)
#define GL_FX_SIGNALS (GL_FX_SIG_W + GL_FX_M)

/** Bits of ::gl_fixed_loop_t::flags. */
#define GL_FX_FAULT 1u    /**< A y or r was not finite: the safe command, state untouched. */
#define GL_FX_CLIPPED 2u  /**< A sample or reference was outside its declared range and clipped. */
#define GL_FX_OVERFLOW 4u /**< The second-line saturation had to clip (which variables: overflow_mask). */

/** Bits of ::gl_fixed_loop_t::overflow_mask: which saturation fired. */
#define GL_FX_OVF_DY 1u
#define GL_FX_OVF_V 2u
#define GL_FX_OVF_DU 4u
#define GL_FX_OVF_W 8u /**< Uv - V */
#define GL_FX_OVF_Z 16u
#define GL_FX_OVF_XH 32u

/**
 * @brief The certified integers (generated, const, may live in flash).
 *
 * The sums' non-zero coefficients row by row: terms `row_end[i-1] .. row_end[i]-1` of row i, each a mantissa
 * `coef`, a left shift `shift` (the `*_shift` tables of the artifact) and the index `signal` of what it
 * multiplies in ::gl_fixed_loop_t::sig.
 */
typedef struct {
    gl_fx_coef_t coef[GL_FX_TERMS_A];  /**< mantissas */
    uint8_t shift[GL_FX_TERMS_A];      /**< left shift of each product into its row's accumulator */
    uint8_t signal[GL_FX_TERMS_A];     /**< index into sig[] */
    uint16_t row_end[GL_FX_ROWS];      /**< one past each row's last term */
    int8_t row_shift[GL_FX_ROWS];      /**< shift_v, shift_z, shift_x: accumulator to output format */
    int8_t shift_u[GL_FX_M];           /**< v format to command format (negative: exact left shift) */
    int32_t uop_v[GL_FX_M];            /**< u_op, v formats */
    int32_t lo_v[GL_FX_M];             /**< limits, v formats */
    int32_t hi_v[GL_FX_M];
    gl_fx_word_t uop_u[GL_FX_M];       /**< u_op, command formats */
    gl_fx_word_t u_safe[GL_FX_M];      /**< u_op clamped into the limits, command formats */
    gl_fx_word_t yop[GL_FX_P];         /**< y_op, sample formats */
    int32_t xh0[GL_FX_N];              /**< initial estimate */
    int32_t z0[GL_FX_QA];              /**< initial integrators */
    int8_t frac_y[GL_FX_P];            /**< fractional bits of the samples */
    int8_t frac_r[GL_FX_QA];           /**< ... of the references */
    int8_t frac_u[GL_FX_M];            /**< ... of the commands */
    int32_t key_y_lo[GL_FX_P];         /**< y_min as the order key (gl_fixed_key) of the least float >= y_min */
    int32_t key_y_hi[GL_FX_P];         /**< y_max as the key of the greatest float <= y_max */
    int32_t key_r_lo[GL_FX_QA];
    int32_t key_r_hi[GL_FX_QA];
    gl_fx_word_t y_lo[GL_FX_P];        /**< quantise(y_min, f_y): the sample a clipped-low y becomes */
    gl_fx_word_t y_hi[GL_FX_P];
    gl_fx_word_t r_lo[GL_FX_QA];
    gl_fx_word_t r_hi[GL_FX_QA];
    float u_lsb[GL_FX_M];              /**< 2^-f_u: the command word's value in the command's units */
    uint8_t clamp;                     /**< anti-windup clamp: hold Z on a saturated step */
} gl_fixed_gains_t;

/**
 * @brief A gain set of the integer law as an upload changes it: the integers, the CRC-32 of its gain values (the
 *        MAVLink table's `GL_HASH`, gl_fixed_set_crc32()) and the compatibility signature of the law it was made for
 *        (GL_LAW_SIGNATURE of gl_law.h: dimensions, number formats, the terms' signals and the declared ranges).
 */
typedef struct {
    gl_fixed_gains_t g;  /**< The integers (first: a pointer to the set is one to them). */
    uint32_t crc32;      /**< gl_fixed_set_crc32() of the set. */
    uint32_t signature;  /**< The law's compatibility signature. */
} gl_fixed_set_t;

/** @brief The artifact's certified integers as a set (generated gl_fixed_gains.c). */
extern const gl_fixed_set_t gl_fixed_default;

/** @brief Loop state and the last step's outputs (caller-owned; no dynamic memory). */
typedef struct {
    const gl_fixed_gains_t *g;      /**< the integers */
    int32_t sig[GL_FX_SIGNALS];     /**< XH, dY, Z (the state), dU, R, Y, Uv - V of the last step */
    int32_t v[GL_FX_M];             /**< unsaturated command V (v formats) of the last step */
    gl_fx_word_t u[GL_FX_M];        /**< command word U (command formats) of the last step */
    uint32_t flags;                 /**< GL_FX_FAULT | GL_FX_CLIPPED | GL_FX_OVERFLOW of the last step */
    uint32_t sat_mask;              /**< bit i: command i saturated at its limit */
    uint32_t clip_mask;             /**< bit k: sample k clipped; bit GL_FX_P + j: reference j clipped */
    uint32_t overflow_mask;         /**< GL_FX_OVF_* bits of the saturations that fired */
} gl_fixed_loop_t;

/**
 * @brief Start a loop on gain set `g` (normally &gl_fixed_default.g): XH = XH0, Z = Z0, U = U_SAFE.
 * @param[out] loop The loop.
 * @param[in] g The integers.
 * @return 0, or -1 when an argument is NULL.
 */
int gl_fixed_init(gl_fixed_loop_t *loop, const gl_fixed_gains_t *g);

/** @brief Back to the initial estimate and integrators. @param[in,out] loop The loop. */
void gl_fixed_reset(gl_fixed_loop_t *loop);

/**
 * @brief One step of the integer law (see the file comment).
 * @param[in,out] loop The loop (its flags and masks tell what happened in this step).
 * @param[in] y Samples (GL_FX_P), absolute.
 * @param[in] r References (GL_FX_Q; may be NULL when GL_FX_Q is 0).
 * @param[out] u Commands (GL_FX_M) as floats: the command words times 2^-f_u (loop->u holds the words).
 * @return The step's flags (GL_FX_FAULT, GL_FX_CLIPPED, GL_FX_OVERFLOW; 0 for a clean step).
 */
uint32_t gl_fixed_step(gl_fixed_loop_t *loop, const float *y, const float *r, float *u);

/**
 * @brief The command words of the last step (or the safe command after gl_fixed_reset()) as floats, U 2^-f_u: the
 *        conversion gl_fixed_step() ends with, for a caller that changed the words (a watchdog's safe command).
 * @param[in] loop The loop. @param[out] u GL_FX_M commands.
 */
void gl_fixed_command(const gl_fixed_loop_t *loop, float *u);

/**
 * @brief Whether a set's integers can run on this build: its structure (each term's signal, the rows' ends and
 *        rounding shifts, formats, declared ranges, anti-windup) is the compiled one's, and its values are in range
 *        (left shifts 0..62, LO_V <= HI_V).
 * @param[in] g The integers.
 * @return 0; -1 when the structure differs from the compiled set's; -2 when a value is out of range.
 */
int gl_fixed_check(const gl_fixed_gains_t *g);

/**
 * @brief CRC-32 (zlib's) of a set's gain values as little-endian int32 words, in the order of the MAVLink table
 *        (gainlink.shipping.params): each term's mantissa and shift, then UOP_V, LO_V, HI_V, UOP_U, U_SAFE, YOP,
 *        XH0, Z0.
 * @param[in] g The integers. @return The checksum.
 */
uint32_t gl_fixed_set_crc32(const gl_fixed_gains_t *g);

/**
 * @brief A float's order key: an int32 that orders as the float does (non-NaN), used to clip without float
 *        comparisons. @param[in] x The float. @return The key.
 */
int32_t gl_fixed_key(float x);

#endif /* GAINLINK_GL_FIXED_H */
