/**
 * @file gl_fixed_host.c
 * @brief Host port of the fixed-point loop: the entry points the Python ctypes bindings call — a run of
 *        recorded samples (gainlink.firmware.fixed) and a loop stepped one sample at a time (SIL:
 *        gainlink.engines.fixed_native), the loop object in the caller's memory.
 */
#include <stddef.h>
#include <stdint.h>

#include "gl_fixed_record.h"

/** @brief Words of one output record (gl_fixed_record.h). @return GL_FX_RECORD_WORDS. */
uint32_t gl_fixed_host_record_words(void)
{
    return GL_FX_RECORD_WORDS;
}

/** @brief The signature of the number formats the library was built for. @return GL_FX_SIGNATURE. */
const char *gl_fixed_host_signature(void)
{
    return GL_FX_SIGNATURE;
}

/**
 * @brief Run `count` steps from the initial state.
 * @param[in] y Samples, count x GL_FX_P.
 * @param[in] r References, count x GL_FX_QA (ignored when GL_FX_Q is 0).
 * @param[in] count Steps.
 * @param[out] out count records (gl_fixed_record_t).
 * @return 0.
 */
int gl_fixed_host_run(const float *y, const float *r, uint32_t count, gl_fixed_record_t *out)
{
    gl_fixed_loop_t loop;
    float u[GL_FX_M];
    (void)gl_fixed_init(&loop, &gl_fixed_gains_default);
    for (uint32_t k = 0; k < count; ++k) {
        (void)gl_fixed_step(&loop, &y[(size_t)k * GL_FX_P], &r[(size_t)k * GL_FX_QA], u);
        gl_fixed_record(&loop, u, &out[k]);
    }
    return 0;
}

/** @brief Bytes of one gl_fixed_loop_t (the caller allocates it). @return sizeof(gl_fixed_loop_t). */
uint32_t gl_fixed_host_loop_bytes(void)
{
    return (uint32_t)sizeof(gl_fixed_loop_t);
}

/**
 * @brief Initialise `loop` with the artifact's gains (gl_fixed_gains_default), its initial state.
 * @param[out] loop The loop (gl_fixed_host_loop_bytes() bytes).
 * @return gl_fixed_init's result (0: done).
 */
int gl_fixed_host_init(gl_fixed_loop_t *loop)
{
    return gl_fixed_init(loop, &gl_fixed_gains_default);
}

/**
 * @brief One step of `loop` on sample `y` and references `r`.
 * @param[in,out] loop The loop.
 * @param[in] y GL_FX_P samples.
 * @param[in] r GL_FX_QA references (ignored when GL_FX_Q is 0).
 * @param[out] out The step's record (gl_fixed_record_t).
 * @return The step's flags (gl_fixed_step).
 */
uint32_t gl_fixed_host_step(gl_fixed_loop_t *loop, const float *y, const float *r, gl_fixed_record_t *out)
{
    float u[GL_FX_M];
    const uint32_t flags = gl_fixed_step(loop, y, r, u);
    gl_fixed_record(loop, u, out);
    return flags;
}
