/**
 * @file gl_fma.h
 * @brief GL_FMA, the one fused multiply-add every gainlink step uses (library-internal).
 *
 * Fused multiply-add a*b+c, rounded once: `vfma.f32` on a core with an FPU, libm `fmaf` on the host, and
 * gl_fmaf() (integer arithmetic, gl_fmaf.c) on a core without one (Cortex-M0, M3), where newlib's `fmaf`
 * rounds twice. Benchmark baselines only (CMake GL_SOFT_FMA, soft-float targets; not bit for bit with the
 * host): `newlib` calls newlib's `fmaf`, `plain` is a multiply then an add, each rounded.
 */
#ifndef GAINLINK_GL_FMA_H
#define GAINLINK_GL_FMA_H

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

#endif /* GAINLINK_GL_FMA_H */
