/**
 * @file gl_mav_schedparams.c
 * @brief The parameter table of a scheduled law (gl_mav_params.h, GL_MAV_LAW_SCHED): read-only, the compiled
 *        structure and GL_HASH, the CRC-32 of the compiled tables. The same API as gl_mav_params.c, which an
 *        unscheduled float32 build compiles instead; no gain of the points is a parameter yet.
 */
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "gl_mav_params.h"

static const char *const header_ids[GL_MAV_HEADER_PARAMS] = {"GL_DIM_N", "GL_DIM_M", "GL_DIM_P", "GL_DIM_Q",
                                                             "GL_NPTS",  "GL_DIM_E", "GL_HASH"};

/** CRC-32 (zlib's) of `n` bytes. */
static uint32_t crc32_bytes(const uint8_t *b, size_t n)
{
    uint32_t c = 0xFFFFFFFFu;
    for (size_t k = 0; k < n; ++k) {
        c ^= b[k];
        for (unsigned i = 0; i < 8u; ++i) {
            c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
        }
    }
    return ~c;
}

const gl_mav_set_t *gl_mav_sched_default_set(void)
{
    static gl_mav_set_t set;
    if (set.t == NULL) {
        set.crc32 = crc32_bytes((const uint8_t *)&gl_sched_default, sizeof gl_sched_default);
        set.t = &gl_sched_default;
    }
    return &set;
}

void gl_mav_params_init(gl_mav_params_t *table, const gl_mav_set_t *gains)
{
    memset(table, 0, sizeof *table);
    for (int32_t h = 0; h < GL_MAV_HEADER_PARAMS; ++h) {
        gl_mav_param_t *p = &table->param[h];
        snprintf(p->id, sizeof p->id, "%s", header_ids[h]);
        p->type = GL_MAV_TYPE_INT32;
        p->header = h;
    }
    table->count = GL_MAV_HEADER_PARAMS;
    table->staged = *gains;
    table->committed = *gains;
}

int32_t gl_mav_params_find(const gl_mav_params_t *table, const char *id)
{
    char key[GL_MAV_ID_LEN + 1];
    memcpy(key, id, GL_MAV_ID_LEN);
    key[GL_MAV_ID_LEN] = '\0';
    for (uint16_t k = 0; k < table->count; ++k) {
        if (strncmp(table->param[k].id, key, GL_MAV_ID_LEN) == 0) {
            return (int32_t)k;
        }
    }
    return -1;
}

float gl_mav_params_value(const gl_mav_params_t *table, uint16_t index)
{
    const uint32_t words[GL_MAV_HEADER_PARAMS] = {GL_N, GL_M, GL_P, GL_Q, GL_NPTS, GL_E, table->committed.crc32};
    float f;
    memcpy(&f, &words[table->param[index].header], sizeof f);
    return f;
}

gl_mav_set_result_t gl_mav_params_set(gl_mav_params_t *table, uint16_t index, float value, uint8_t type)
{
    (void)value;
    return type != table->param[index].type ? GL_MAV_SET_BAD_TYPE : GL_MAV_SET_READ_ONLY;
}

gl_status_t gl_mav_params_replace(gl_mav_params_t *table, const gl_mav_set_t *gains)
{
    if (gains->t != &gl_sched_default || gains->crc32 != gl_mav_sched_default_set()->crc32) {
        return GL_SCHED_ERR_RANGE; /* only the compiled tables run here */
    }
    table->staged = *gains;
    table->committed = *gains;
    table->commits++;
    return GL_OK;
}

uint32_t gl_mav_params_bits(const gl_mav_set_t *set, uint32_t offset)
{
    (void)set;
    (void)offset;
    return 0u; /* no gain parameters */
}

void gl_mav_params_put_bits(gl_mav_set_t *set, uint32_t offset, uint32_t bits)
{
    (void)set;
    (void)offset;
    (void)bits;
}
