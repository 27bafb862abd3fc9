/**
 * @file gl_host.c
 * @brief Host port: the entry points the Python ctypes bindings (gainlink.engines) call, for whichever law the build
 *        runs (gl_law.h). The law's instance lives in the caller's memory (gl_host_law_bytes()); a step answers with
 *        the law's record (GL_LAW_RECORD_HEADER of gl_law.h), which gainlink.shipping.records reads as a numpy dtype.
 */
#include <stddef.h>
#include <stdint.h>

#include "gainlink/gl_law.h"

/** @brief sizeof(gl_law_t), so a binding can allocate the instance. @return Size in bytes. */
size_t gl_host_law_bytes(void);
/** @brief sizeof(gl_law_gains_t), so a binding can check its own layout. @return Size in bytes. */
size_t gl_host_gains_bytes(void);
/** @brief sizeof(gl_law_record_t). @return Size in bytes. */
size_t gl_host_record_bytes(void);
/** @brief sizeof(gl_law_sample_t). @return Size in bytes. */
size_t gl_host_sample_bytes(void);
/** @brief The generated gain set of the artifact this library was built for. @return Its address. */
const gl_law_gains_t *gl_host_default_gains(void);
/** @brief sha256 of the artifact this library was built for. @return A NUL-terminated hex string. */
const char *gl_host_artifact_sha256(void);
/** @brief The law it runs (GL_LAW_NAME: float32, q31, q15, scheduled-float32). @return A NUL-terminated name. */
const char *gl_host_law_name(void);
/** @brief gl_law_init(). @param[out] law Instance. @param[in] watchdog_periods Idle periods. @return Status. */
int32_t gl_host_law_init(gl_law_t *law, uint32_t watchdog_periods);
/**
 * @brief gl_law_step() and its record.
 * @param[in,out] law Instance. @param[in] y GL_P samples. @param[in] r GL_QA references. @param[in] s GL_LAW_EA
 * external signals. @param[out] rec The record. @return The step's status.
 */
int32_t gl_host_law_step(gl_law_t *law, const float *y, const float *r, const float *s, gl_law_record_t *rec);
/** @brief gl_law_idle() and its record. @param[in,out] law Instance. @param[out] rec Record. @return Status. */
int32_t gl_host_law_idle(gl_law_t *law, gl_law_record_t *rec);
/** @brief gl_law_reset() and its record. @param[in,out] law Instance. @param[out] rec Record. @return Status. */
int32_t gl_host_law_reset(gl_law_t *law, gl_law_record_t *rec);
/** @brief gl_law_stage(). @param[in,out] law Instance. @param[in] gains Set (kept by address). @return Status. */
int32_t gl_host_law_stage(gl_law_t *law, const gl_law_gains_t *gains);
/** @brief gl_law_active_crc32(). @param[in] law Instance. @return The running set's checksum. */
uint32_t gl_host_law_active_crc32(const gl_law_t *law);
/**
 * @brief A block of samples (replay engines), one call: each sample's tag says what the law does with it (a step,
 *        an idle period or a reset; a stage record is answered with status GL_ERR_NULL: stage with
 *        gl_host_law_stage()).
 * @param[in,out] law Instance. @param[in] count Samples. @param[in] in count samples. @param[out] out count records.
 */
void gl_host_law_run(gl_law_t *law, uint32_t count, const gl_law_sample_t *in, gl_law_record_t *out);
/**
 * @brief One sample for each of many instances (a campaign block), one call: instance i takes in[i] (a step, an
 *        idle period or a reset by its tag, as gl_host_law_run()) and answers out[i]. Each instance keeps its own
 *        state and gain set (gl_host_law_stage()); the operations per instance are those of gl_host_law_step().
 * @param[in,out] laws count instances, contiguous (gl_host_law_bytes() each). @param[in] count Instances.
 * @param[in] in count samples. @param[out] out count records.
 */
void gl_host_law_step_block(gl_law_t *laws, uint32_t count, const gl_law_sample_t *in, gl_law_record_t *out);

size_t gl_host_law_bytes(void)
{
    return sizeof(gl_law_t);
}

size_t gl_host_gains_bytes(void)
{
    return sizeof(gl_law_gains_t);
}

size_t gl_host_record_bytes(void)
{
    return sizeof(gl_law_record_t);
}

size_t gl_host_sample_bytes(void)
{
    return sizeof(gl_law_sample_t);
}

const gl_law_gains_t *gl_host_default_gains(void)
{
    return GL_LAW_DEFAULT_GAINS;
}

const char *gl_host_artifact_sha256(void)
{
    return gl_artifact_sha256;
}

const char *gl_host_law_name(void)
{
    return GL_LAW_NAME;
}

int32_t gl_host_law_init(gl_law_t *law, uint32_t watchdog_periods)
{
    return (int32_t)gl_law_init(law, watchdog_periods);
}

/* The exported entry points and gl_host_law_run() share these (a call between exported functions of a shared
 * library goes through its PLT). */
static inline int32_t host_step(gl_law_t *law, const float *y, const float *r, const float *s, gl_law_record_t *rec)
{
    gl_law_out_t out;
    const gl_status_t st = gl_law_step(law, y, GL_Q > 0 ? r : NULL, GL_LAW_E > 0 ? s : NULL, &out);
    gl_law_record(law, &out, rec);
    return (int32_t)st;
}

static inline int32_t host_idle(gl_law_t *law, gl_law_record_t *rec)
{
    gl_law_out_t out;
    const gl_status_t st = gl_law_idle(law, &out);
    gl_law_record(law, &out, rec);
    return (int32_t)st;
}

static inline int32_t host_reset(gl_law_t *law, gl_law_record_t *rec)
{
    gl_law_out_t out;
    const gl_status_t st = gl_law_reset(law, &out);
    gl_law_record(law, &out, rec);
    return (int32_t)st;
}

int32_t gl_host_law_step(gl_law_t *law, const float *y, const float *r, const float *s, gl_law_record_t *rec)
{
    return host_step(law, y, r, s, rec);
}

int32_t gl_host_law_idle(gl_law_t *law, gl_law_record_t *rec)
{
    return host_idle(law, rec);
}

int32_t gl_host_law_reset(gl_law_t *law, gl_law_record_t *rec)
{
    return host_reset(law, rec);
}

int32_t gl_host_law_stage(gl_law_t *law, const gl_law_gains_t *gains)
{
    return (int32_t)gl_law_stage(law, gains);
}

uint32_t gl_host_law_active_crc32(const gl_law_t *law)
{
    return gl_law_active_crc32(law);
}

/* One sample by its tag (a stage record is answered with status GL_ERR_NULL). */
static inline void host_sample(gl_law_t *law, const gl_law_sample_t *x, gl_law_record_t *out)
{
    if (x->tag == GL_LAW_TAG_STEP) {
        (void)host_step(law, x->y, x->r, x->s, out);
    } else if (x->tag == GL_LAW_TAG_IDLE) {
        (void)host_idle(law, out);
    } else if (x->tag == GL_LAW_TAG_RESET) {
        (void)host_reset(law, out);
    } else {
        gl_law_out_t none;
        memset(&none, 0, sizeof none);
        none.status = GL_ERR_NULL;
        gl_law_record(law, &none, out);
    }
}

void gl_host_law_run(gl_law_t *law, uint32_t count, const gl_law_sample_t *in, gl_law_record_t *out)
{
    for (uint32_t k = 0; k < count; ++k) {
        host_sample(law, &in[k], &out[k]);
    }
}

void gl_host_law_step_block(gl_law_t *laws, uint32_t count, const gl_law_sample_t *in, gl_law_record_t *out)
{
    for (uint32_t i = 0; i < count; ++i) {
        host_sample(&laws[i], &in[i], &out[i]);
    }
}
