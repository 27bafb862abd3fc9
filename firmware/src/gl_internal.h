/**
 * @file gl_internal.h
 * @brief Library-internal helpers shared by the gainlink sources (not part of the public API).
 */
#ifndef GAINLINK_GL_INTERNAL_H
#define GAINLINK_GL_INTERNAL_H

#include "gainlink/gl_loop.h"

/**
 * Fused multiply-add a*b+c, rounded once: `vfma.f32` on a core with an FPU, libm `fmaf` on the host, and
 * gl_fmaf() (integer arithmetic, gl_fmaf.c) on a core without one (Cortex-M0, M3), where newlib's `fmaf`
 * rounds twice. Benchmark baselines only (CMake GL_SOFT_FMA, soft-float targets; not bit for bit with the
 * host): `newlib` calls newlib's `fmaf`, `plain` is a multiply then an add, each rounded.
 */
#if defined(__arm__) && !defined(__ARM_FP) && defined(GL_SOFT_FMA_NEWLIB)
#include <math.h>
#define GL_FMA(a, b, c) fmaf((a), (b), (c))
#elif defined(__arm__) && !defined(__ARM_FP) && defined(GL_SOFT_FMA_PLAIN)
#define GL_FMA(a, b, c) ((a) * (b) + (c))
#elif defined(__arm__) && !defined(__ARM_FP)
#include "gl_fmaf.h"
#define GL_FMA(a, b, c) gl_fmaf((a), (b), (c))
#else
#define GL_FMA(a, b, c) __builtin_fmaf((a), (b), (c))
#endif

/**
 * @brief Check a gain set and derive the step's coefficients from it.
 * @param[in]  gains  Candidate set.
 * @param[out] out    Bank to fill (garbage on error; never the active bank).
 * @return GL_OK or the first failing check's error.
 */
gl_status_t gl_coeffs_derive(const gl_gains_t *gains, gl_coeffs_t *out);

#endif /* GAINLINK_GL_INTERNAL_H */
