/**
 * @file gl_host.c
 * @brief Host port: the entry points the Python ctypes binding (gainlink.engines.native) calls.
 */
#include "gl_host.h"

size_t gl_host_loop_size(void)
{
    return sizeof(gl_loop_t);
}

size_t gl_host_gains_size(void)
{
    return sizeof(gl_gains_t);
}

const gl_gains_t *gl_host_default_gains(void)
{
    return &gl_gains_default;
}

const char *gl_host_artifact_sha256(void)
{
    return gl_artifact_sha256;
}

uint32_t gl_host_dims(uint32_t which)
{
#define GL_COMPILED(field, compiled, param) (uint32_t)(compiled),
    static const uint32_t dims[GL_GAINS_STRUCTURE_FIELDS] = {GL_GAINS_STRUCTURE(GL_COMPILED)};
    return which < GL_GAINS_STRUCTURE_FIELDS ? dims[which] : 0u;
}

uint32_t gl_host_sat_mask(const gl_loop_t *loop)
{
    return loop == NULL ? 0u : loop->sat_mask;
}
