/**
 * @file gl_mav_params.c
 * @brief Parameter table of the MAVLink app: ids, staged values, commit through the library's checks.
 */
#include "gl_mav_params.h"

#include <stddef.h>
#include <stdio.h>
#include <string.h>

/** One block of floats of gl_gains_t that is exposed as parameters. */
typedef struct block {
    const char *stem; /**< Id stem after "GL_". */
    size_t field;     /**< offsetof the field in gl_gains_t. */
    uint32_t rank;    /**< 0 scalar (GL_<stem>), 1 vector (GL_<stem>_i), 2 matrix (GL_<stem>_i_j). */
    uint32_t rows;    /**< Rows (vector: elements) exposed; 0 when the block is not a parameter in this build. */
    uint32_t cols;    /**< Columns exposed (1 for a scalar or vector). */
    uint32_t stride;  /**< Declared columns (row stride in floats). */
} block_t;

#define FIELD(name) offsetof(gl_gains_t, name)

/* Both lists come from the field table gainlink.shipping.gains_layout (gl_gains_layout.h), as do runtime/mavlink/params.py's. */
#define GL_BLOCK(name, stem_, rank_, rows_, cols_, stride_) \
    {.stem = stem_, .field = FIELD(name), .rank = rank_, .rows = rows_, .cols = cols_, .stride = stride_},
static const block_t blocks[] = {GL_GAINS_PARAMS(GL_BLOCK)};

#define GL_HEADER_ID(field, compiled, param) param,
static const char *const header_ids[GL_MAV_HEADER_PARAMS] = {GL_GAINS_STRUCTURE(GL_HEADER_ID) "GL_HASH"};


static float *gain_float(gl_gains_t *gains, uint32_t offset)
{
    return &gains->Ts + offset;
}

static const float *gain_float_const(const gl_gains_t *gains, uint32_t offset)
{
    return &gains->Ts + offset;
}

void gl_mav_params_init(gl_mav_params_t *table, const gl_mav_set_t *gains)
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
        for (uint32_t i = 0; i < blk->rows; ++i) {
            for (uint32_t j = 0; j < blk->cols; ++j) {
                gl_mav_param_t *p = &table->param[k++];
                char name[48]; /* i, j < 64: every id fits the 16 characters (checked below) */
                if (blk->rank == 0u) {
                    snprintf(name, sizeof name, "GL_%s", blk->stem);
                } else if (blk->rank == 1u) {
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

float gl_mav_params_value(const gl_mav_params_t *table, uint16_t index)
{
    const gl_mav_param_t *p = &table->param[index];
    const gl_gains_t *c = &table->committed;
    if (p->header >= 0 && p->header < GL_GAINS_STRUCTURE_FIELDS) {
#define GL_STRUCTURE_WORD(field, compiled, param) c->field,
        const uint32_t words[GL_GAINS_STRUCTURE_FIELDS] = {GL_GAINS_STRUCTURE(GL_STRUCTURE_WORD)};
        return gl_mav_float_of_bits(words[p->header]);
    }
    if (p->header == GL_MAV_HASH_HEADER) {
        return gl_mav_float_of_bits(c->crc32);
    }
    return *gain_float_const(&table->staged, p->offset);
}

gl_status_t gl_mav_params_replace(gl_mav_params_t *table, const gl_mav_set_t *gains)
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

uint32_t gl_mav_params_bits(const gl_mav_set_t *set, uint32_t offset)
{
    uint32_t bits;
    memcpy(&bits, gain_float_const(set, offset), sizeof bits);
    return bits;
}

void gl_mav_params_put_bits(gl_mav_set_t *set, uint32_t offset, uint32_t bits)
{
    memcpy(gain_float(set, offset), &bits, sizeof bits);
}
