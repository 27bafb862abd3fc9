/**
 * @file gl_sched_host.c
 * @brief Host port of the scheduled loop: the entry points the Python ctypes binding
 *        (gainlink.engines.sched_native) calls beside the gl_sched.h API.
 */
#include <stddef.h>

#include "gainlink/gl_sched.h"

/** @brief sizeof(gl_sched_t), so a binding can allocate the instance. @return Size in bytes. */
size_t gl_host_sched_size(void);
/** @brief The generated tables of the artifact this library was built for. @return Their address. */
const gl_sched_tables_t *gl_host_sched_default(void);
/** @brief sha256 of the artifact this library was built for. @return A NUL-terminated hex string. */
const char *gl_host_artifact_sha256(void);

size_t gl_host_sched_size(void)
{
    return sizeof(gl_sched_t);
}

const gl_sched_tables_t *gl_host_sched_default(void)
{
    return &gl_sched_default;
}

const char *gl_host_artifact_sha256(void)
{
    return gl_artifact_sha256;
}
