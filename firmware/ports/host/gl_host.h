/**
 * @file gl_host.h
 * @brief Host port helpers for language bindings (sizes, the built-in gain set, identity).
 */
#ifndef GAINLINK_GL_HOST_H
#define GAINLINK_GL_HOST_H

#include <stddef.h>
#include <stdint.h>

#include "gainlink/gl_loop.h"

/** @brief sizeof(gl_loop_t), so a binding can allocate the instance. @return Size in bytes. */
size_t gl_host_loop_size(void);

/** @brief sizeof(gl_gains_t), so a binding can check its own layout. @return Size in bytes. */
size_t gl_host_gains_size(void);

/** @brief The generated gain set of the artifact this library was built for. @return Its address. */
const gl_gains_t *gl_host_default_gains(void);

/** @brief sha256 of the artifact this library was built for. @return A NUL-terminated hex string. */
const char *gl_host_artifact_sha256(void);

/**
 * @brief Compiled structure.
 * @param[in] which 0..5 for n, m, p, q, observer form, anti-windup mode.
 * @return The value, 0 for an unknown index.
 */
uint32_t gl_host_dims(uint32_t which);

/**
 * @brief Saturation mask of the last step.
 * @param[in] loop Loop instance.
 * @return Bit k set when input k saturated (0 if loop is NULL).
 */
uint32_t gl_host_sat_mask(const gl_loop_t *loop);

#endif /* GAINLINK_GL_HOST_H */
