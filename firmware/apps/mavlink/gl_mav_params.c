/**
 * @file gl_mav_params.c
 * @brief Parameter table of the MAVLink app: ids, staged values, commit through the library's checks.
 */
#include "gl_mav_params.h"

#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

/** One block of floats of gl_gains_t that is exposed as parameters. */
typedef struct block {
    const char *stem;  /**< Id stem after "GL_". */
    size_t field;      /**< offsetof the field in gl_gains_t. */
    uint32_t rows;     /**< Rows exposed. */
    uint32_t cols;     /**< Columns exposed (0 for a vector). */
    uint32_t stride;   /**< Declared columns (row stride in floats). */
} block_t;

#define FIELD(name) offsetof(gl_gains_t, name)

static const block_t blocks[] = {
    {.stem = "TS", .field = FIELD(Ts), .rows = 1, .cols = 0, .stride = 1},
    {.stem = "AD", .field = FIELD(Ad), .rows = GL_N, .cols = GL_N, .stride = GL_N},
    {.stem = "BD", .field = FIELD(Bd), .rows = GL_N, .cols = GL_M, .stride = GL_M},
    {.stem = "CD", .field = FIELD(Cd), .rows = GL_P, .cols = GL_N, .stride = GL_N},
    {.stem = "DD", .field = FIELD(Dd), .rows = GL_P, .cols = GL_M, .stride = GL_M},
    {.stem = "K", .field = FIELD(K), .rows = GL_M, .cols = GL_N, .stride = GL_N},
    {.stem = "L", .field = FIELD(L), .rows = GL_N, .cols = GL_P, .stride = GL_P},
    {.stem = "M", .field = FIELD(M), .rows = (GL_OBSERVER_FORM == GL_FORM_CURRENT) ? GL_N : 0, .cols = GL_P, .stride = GL_P},
    {.stem = "CI", .field = FIELD(Ci), .rows = GL_Q, .cols = GL_P, .stride = GL_P},
    {.stem = "KI", .field = FIELD(Ki), .rows = (GL_Q > 0) ? GL_M : 0, .cols = GL_Q, .stride = GL_QA},
    {.stem = "KAW", .field = FIELD(Kaw), .rows = GL_Q, .cols = GL_M, .stride = GL_M},
    {.stem = "UMIN", .field = FIELD(u_min), .rows = GL_M, .cols = 0, .stride = 1},
    {.stem = "UMAX", .field = FIELD(u_max), .rows = GL_M, .cols = 0, .stride = 1},
    {.stem = "XH0", .field = FIELD(xh0), .rows = GL_N, .cols = 0, .stride = 1},
    {.stem = "Z0", .field = FIELD(z0), .rows = GL_Q, .cols = 0, .stride = 1},
    {.stem = "UOP", .field = FIELD(u_op), .rows = GL_M, .cols = 0, .stride = 1},
    {.stem = "YOP", .field = FIELD(y_op), .rows = GL_P, .cols = 0, .stride = 1},
};

static const char *const header_ids[GL_MAV_HEADER_PARAMS] = {
    "GL_DIM_N", "GL_DIM_M", "GL_DIM_P", "GL_DIM_Q", "GL_FORM", "GL_AW", "GL_HASH",
};

/** Index of the GL_HASH entry among the header parameters. */
#define HASH_HEADER 6

static float *gain_float(gl_gains_t *gains, uint32_t offset)
{
    return &gains->Ts + offset;
}

static const float *gain_float_const(const gl_gains_t *gains, uint32_t offset)
{
    return &gains->Ts + offset;
}

void gl_mav_params_init(gl_mav_params_t *table, const gl_gains_t *gains)
{
    memset(table, 0, sizeof *table);
    uint16_t k = 0;
    for (int32_t h = 0; h < GL_MAV_HEADER_PARAMS; ++h) {
        gl_mav_param_t *p = &table->param[k++];
        snprintf(p->id, sizeof p->id, "%s", header_ids[h]);
        p->type = GL_MAV_TYPE_INT32;
        p->header = h;
    }
    for (size_t b = 0; b < sizeof blocks / sizeof blocks[0]; ++b) {
        const block_t *blk = &blocks[b];
        uint32_t base = (uint32_t)((blk->field - FIELD(Ts)) / sizeof(float));
        uint32_t cols = blk->cols == 0u ? 1u : blk->cols;
        for (uint32_t i = 0; i < blk->rows; ++i) {
            for (uint32_t j = 0; j < cols; ++j) {
                gl_mav_param_t *p = &table->param[k++];
                char name[48]; /* i, j < 64: every id fits the 16 characters (checked below) */
                if (blk->cols == 0u && blk->rows == 1u && strcmp(blk->stem, "TS") == 0) {
                    snprintf(name, sizeof name, "GL_%s", blk->stem);
                } else if (blk->cols == 0u) {
                    snprintf(name, sizeof name, "GL_%s_%u", blk->stem, (unsigned)i);
                } else {
                    snprintf(name, sizeof name, "GL_%s_%u_%u", blk->stem, (unsigned)i, (unsigned)j);
                }
                memcpy(p->id, name, GL_MAV_ID_LEN);
                p->id[GL_MAV_ID_LEN] = '\0';
                p->type = GL_MAV_TYPE_REAL32;
                p->header = -1;
                p->offset = base + i * blk->stride + j;
            }
        }
    }
    table->count = k;
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

static float int_bits(uint32_t v)
{
    float f;
    memcpy(&f, &v, sizeof f);
    return f;
}

float gl_mav_params_value(const gl_mav_params_t *table, uint16_t index)
{
    const gl_mav_param_t *p = &table->param[index];
    const gl_gains_t *c = &table->committed;
    switch (p->header) {
    case 0: return int_bits(c->n);
    case 1: return int_bits(c->m);
    case 2: return int_bits(c->p);
    case 3: return int_bits(c->q);
    case 4: return int_bits(c->observer_form);
    case 5: return int_bits(c->anti_windup);
    case HASH_HEADER: return int_bits(c->crc32);
    default: return *gain_float_const(&table->staged, p->offset);
    }
}

gl_mav_set_result_t gl_mav_params_set(gl_mav_params_t *table, uint16_t index, float value, uint8_t type)
{
    const gl_mav_param_t *p = &table->param[index];
    if (type != p->type) {
        return GL_MAV_SET_BAD_TYPE;
    }
    if (p->header >= 0 && p->header != HASH_HEADER) {
        return GL_MAV_SET_READ_ONLY;
    }
    if (p->header == HASH_HEADER) {
        static gl_loop_t probe; /* full check and derivation without touching the running loop */
        gl_gains_t candidate = table->staged;
        memcpy(&candidate.crc32, &value, sizeof candidate.crc32);
        gl_status_t st = gl_loop_init(&probe, &candidate, 1u);
        if (st != GL_OK) {
            table->last_refusal = (int32_t)st;
            return GL_MAV_SET_BAD_VALUE;
        }
        table->committed = candidate;
        table->staged = candidate;
        table->commits++;
        return GL_MAV_SET_OK;
    }
    if (!isfinite(value)) {
        return GL_MAV_SET_BAD_VALUE;
    }
    *gain_float(&table->staged, p->offset) = value;
    return GL_MAV_SET_OK;
}

gl_status_t gl_mav_params_replace(gl_mav_params_t *table, const gl_gains_t *gains)
{
    static gl_loop_t probe;
    gl_status_t st = gl_loop_init(&probe, gains, 1u);
    if (st != GL_OK) {
        return st;
    }
    table->staged = *gains;
    table->committed = *gains;
    table->commits++;
    return GL_OK;
}
