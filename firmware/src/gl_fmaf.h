/**
 * @file gl_fmaf.h
 * @brief Correctly rounded float fused multiply-add for cores without an FPU (library-internal).
 */
#ifndef GAINLINK_GL_FMAF_H
#define GAINLINK_GL_FMAF_H

/**
 * @brief a * b + c rounded once to the nearest float (ties to even), as IEEE 754 fusedMultiplyAdd.
 *
 * Integer arithmetic only: the soft-float targets (Cortex-M0, M3) use it for every multiply-add of the
 * step, so their results equal the host's `fmaf` and an FPU's `vfma.f32` bit for bit. Round-to-nearest
 * only; no floating-point exception flags.
 * @param[in] a Factor.
 * @param[in] b Factor.
 * @param[in] c Addend.
 * @return The correctly rounded a * b + c.
 */
float gl_fmaf(float a, float b, float c);

#endif /* GAINLINK_GL_FMAF_H */
