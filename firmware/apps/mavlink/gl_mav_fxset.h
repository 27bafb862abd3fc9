/**
 * @file gl_mav_fxset.h
 * @brief The MAVLink parameter table of a fixed-point law: its integer gains (gl_mav_fxparams.c).
 *
 * Naming scheme, in index order (all INT32, integers bytewise; runtime/mavlink/fixed_params.py builds the same list
 * from the artifact's `checks.fixed_point.integers`):
 * - `GL_DIM_N GL_DIM_M GL_DIM_P GL_DIM_Q GL_FORM GL_AW` (read-only): compiled structure, as the float table's.
 * - `GL_FX_SIG` (read-only): the artifact's signature of the number formats (`checks.fixed_point.signature`, its 8
 *   hex digits as a 32-bit word): the formats of every signal and accumulator, compiled into the law.
 * - `GL_FX_STRUCT` (read-only): CRC-32 of what else is compiled in: each term's signal, each row's end and the
 *   declared ranges (clip keys and quantised bounds), as little-endian int32 words.
 * - `GL_HASH`: CRC-32 of the gain parameters' values below, as little-endian int32 words in index order. Setting it
 *   to the CRC of the staged values commits them: the mantissas must fit the coefficient word, the shifts 0..62,
 *   the operating point and safe command the sample and command words, `LO_V <= HI_V`; then the set is swapped in
 *   between two steps (the state is kept: its formats are the same). Anything else is refused, nothing changes.
 * - each non-zero term of the law's sums (row by row: the m commands, q integrators, n estimates), as
 *   `checks.fixed_point.integers` names its block: `GL_<B>_i_j` its mantissa and `GL_<B>E_i_j` its left shift,
 *   B one of KX KY KZ (command rows), TR TY KAW (integrators), F G LY (estimates);
 * - `GL_UOPV_i GL_LOV_i GL_HIV_i` (v formats), `GL_UOPU_i GL_USAFE_i` (command formats), `GL_YOP_i`, `GL_XH0_i`,
 *   `GL_Z0_i` (q > 0 only).
 * A float (REAL32) set is refused with PARAM_ERROR (wrong type): this target runs integers.
 */
#ifndef GL_MAV_FXSET_H
#define GL_MAV_FXSET_H

#include <stdint.h>

#include "gainlink/gl_fixed.h"

/** Number of integer gain parameters. */
#define GL_MAV_FX_VALUES (2 * GL_FX_TERMS + 5 * GL_FX_M + GL_FX_P + GL_FX_N + GL_FX_Q)

/** A gain set: the integers the law runs, their parameter values and the values' CRC-32. */
typedef struct gl_mav_fx_set {
    gl_fixed_gains_t g;           /**< The integers (structure and formats from the compiled set). */
    int32_t v[GL_MAV_FX_VALUES];  /**< The gain parameters' values, in index order. */
    uint32_t crc32;               /**< CRC-32 of v (GL_HASH). */
} gl_mav_fx_set_t;

/** @brief The compiled set (gl_fixed_gains_default). @return It. */
const gl_mav_fx_set_t *gl_mav_fx_default(void);

#endif /* GL_MAV_FXSET_H */
