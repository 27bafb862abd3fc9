/**
 * @file gl_internal.h
 * @brief Library-internal helpers shared by the gainlink sources (not part of the public API).
 */
#ifndef GAINLINK_GL_INTERNAL_H
#define GAINLINK_GL_INTERNAL_H

#include "gainlink/gl_loop.h"

#include "gl_fma.h" /* GL_FMA */

/**
 * @brief Check a gain set and derive the step's coefficients from it.
 * @param[in]  gains  Candidate set.
 * @param[out] out    Bank to fill (garbage on error; never the active bank).
 * @return GL_OK or the first failing check's error.
 */
gl_status_t gl_coeffs_derive(const gl_gains_t *gains, gl_coeffs_t *out);

#endif /* GAINLINK_GL_INTERNAL_H */
