/**
 * @file gl_fixed_host.c
 * @brief Host port of the fixed-point loop: the entry point the Python ctypes binding
 *        (gainlink.firmware.fixed) calls.
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
