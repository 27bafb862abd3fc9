/**
 * @file gl_mav_schedparams.c
 * @brief The parameter table of a scheduled law (gl_mav_params.h, GL_MAV_LAW_SCHED): every float of its tables (every
 *        point's gains), staged, checked and committed through GL_HASH as one set. The same API as gl_mav_params.c,
 *        which an unscheduled float32 build compiles instead.
 */
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "gl_mav_params.h"

static const char *const header_ids[GL_MAV_HEADER_PARAMS] = {"GL_DIM_N", "GL_DIM_M", "GL_DIM_P", "GL_DIM_Q",
                                                             "GL_NPTS",  "GL_DIM_E", "GL_HASH"};

/** One field of gl_sched_tables_t: `GL_<stem>[_k]_i[_j]` (k a point when per_point, i, j row and column). */
typedef struct block {
    const char *stem;   /**< Id stem after "GL_". */
    size_t field;       /**< offsetof the field. */
    uint32_t per_point; /**< 1: one matrix per point (GL_NPTS of them). */
    uint32_t rank;      /**< 0 scalar, 1 vector, 2 matrix. */
    uint32_t rows;      /**< Rows (vector: elements). */
    uint32_t cols;      /**< Columns (1 for a scalar or vector). */
} block_t;

#define FIELD(name) offsetof(gl_sched_tables_t, name)
static const block_t blocks[] = {
    {"S", FIELD(S), 0, 1, GL_NPTS, 1},      {"KX", FIELD(Kx), 1, 2, GL_M, GL_N},   {"KY", FIELD(Ky), 1, 2, GL_M, GL_P},
    {"KZ", FIELD(Kz), 1, 2, GL_M, GL_Q},    {"F", FIELD(F), 1, 2, GL_N, GL_N},     {"G", FIELD(G), 1, 2, GL_N, GL_M},
    {"LY", FIELD(Ly), 1, 2, GL_N, GL_P},    {"UOP", FIELD(u_op), 1, 1, GL_M, 1},   {"UMIN", FIELD(u_min), 0, 1, GL_M, 1},
    {"UMAX", FIELD(u_max), 0, 1, GL_M, 1},  {"CI", FIELD(Ci), 0, 2, GL_Q, GL_P},   {"ALPHA", FIELD(alpha), 0, 0, 1, 1},
    {"RATE", FIELD(rate_step), 0, 0, 1, 1},
};
_Static_assert(sizeof(gl_sched_tables_t) == sizeof(float) * (GL_MAV_MAX_PARAMS - GL_MAV_HEADER_PARAMS),
               "every float of the tables is a parameter");

/** CRC-32 (zlib's) of the tables' bytes: GL_HASH. */
static uint32_t tables_crc(const gl_sched_tables_t *t)
{
    const uint8_t *b = (const uint8_t *)t;
    uint32_t c = 0xFFFFFFFFu;
    for (size_t k = 0; k < sizeof *t; ++k) {
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
    static int ready;
    if (!ready) {
        set.t = gl_sched_default;
        set.crc32 = tables_crc(&set.t);
        ready = 1;
    }
    return &set;
}

static void name_param(gl_mav_param_t *p, const block_t *blk, uint32_t k, uint32_t i, uint32_t j)
{
    char name[64];
    int at = snprintf(name, sizeof name, "GL_%s", blk->stem);
    if (blk->per_point) {
        at += snprintf(name + at, sizeof name - (size_t)at, "_%u", (unsigned)k);
    }
    if (blk->rank >= 1u) {
        at += snprintf(name + at, sizeof name - (size_t)at, "_%u", (unsigned)i);
    }
    if (blk->rank == 2u) {
        (void)snprintf(name + at, sizeof name - (size_t)at, "_%u", (unsigned)j);
    }
    memcpy(p->id, name, GL_MAV_ID_LEN); /* at most "GL_UMAX_15", "GL_KX_63_15_63": within 16 */
    p->id[GL_MAV_ID_LEN] = '\0';
    p->type = GL_MAV_TYPE_REAL32;
    p->header = -1;
}

void gl_mav_params_init(gl_mav_params_t *table, const gl_mav_set_t *gains)
{
    memset(table, 0, sizeof *table);
    uint16_t n = 0;
    for (int32_t h = 0; h < GL_MAV_HEADER_PARAMS; ++h) {
        gl_mav_param_t *p = &table->param[n++];
        snprintf(p->id, sizeof p->id, "%s", header_ids[h]);
        p->type = GL_MAV_TYPE_INT32;
        p->header = h;
    }
    for (size_t b = 0; b < sizeof blocks / sizeof blocks[0]; ++b) {
        const block_t *blk = &blocks[b];
        const uint32_t points = blk->per_point ? GL_NPTS : 1u;
        uint32_t offset = (uint32_t)(blk->field / sizeof(float));
        for (uint32_t k = 0; k < points; ++k) {
            for (uint32_t i = 0; i < blk->rows; ++i) {
                for (uint32_t j = 0; j < blk->cols; ++j) {
                    gl_mav_param_t *p = &table->param[n++];
                    name_param(p, blk, k, i, j);
                    p->offset = offset++;
                }
            }
        }
    }
    table->count = n;
    table->staged = *gains;
    table->committed = *gains;
}

static float *gain_float(gl_mav_set_t *set, uint32_t offset)
{
    return (float *)(void *)&set->t + offset;
}

float gl_mav_params_value(const gl_mav_params_t *table, uint16_t index)
{
    const gl_mav_param_t *p = &table->param[index];
    float f;
    if (p->header >= 0) {
        const uint32_t words[GL_MAV_HEADER_PARAMS] = {GL_N, GL_M, GL_P, GL_Q, GL_NPTS, GL_E, table->committed.crc32};
        memcpy(&f, &words[p->header], sizeof f);
        return f;
    }
    uint32_t bits = gl_mav_params_bits(&table->staged, p->offset);
    memcpy(&f, &bits, sizeof f);
    return f;
}

/** A candidate set's checks: its CRC, then the loop's own (gl_sched_init on a probe: points, limits, alpha...). */
static gl_status_t check_set(const gl_mav_set_t *set)
{
    static gl_sched_t probe; /* large for a stack; the node runs from one thread */
    if (tables_crc(&set->t) != set->crc32) {
        return GL_SCHED_ERR_RANGE;
    }
    return gl_sched_init(&probe, &set->t);
}

gl_status_t gl_mav_params_replace(gl_mav_params_t *table, const gl_mav_set_t *gains)
{
    gl_status_t st = check_set(gains);
    if (st != GL_OK) {
        return st;
    }
    table->staged = *gains;
    table->committed = *gains;
    table->commits++;
    return GL_OK;
}

uint32_t gl_mav_params_bits(const gl_mav_set_t *set, uint32_t offset)
{
    uint32_t bits;
    memcpy(&bits, (const float *)(const void *)&set->t + offset, sizeof bits);
    return bits;
}

void gl_mav_params_put_bits(gl_mav_set_t *set, uint32_t offset, uint32_t bits)
{
    memcpy(gain_float(set, offset), &bits, sizeof bits);
}
