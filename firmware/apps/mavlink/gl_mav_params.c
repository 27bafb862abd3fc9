/**
 * @file gl_mav_params.c
 * @brief The MAVLink parameter table of the build's law (gl_mav_params.h): find a parameter by id, read it, stage a
 *        value, and commit the staged set when GL_HASH is set to its CRC-32, through the law's own checks.
 */
#include "gl_mav_params.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

/* The entries of the generated table (gl_law_params.h): a gain's place and width in gl_law_gains_t come from the
 * compiler (offsetof, sizeof), its signedness from its C type. */
#define GL_MAV_MEMBER(member) (((gl_law_gains_t *)0)->member)
#define GL_MAV_SIGNED(x) _Generic((x), int8_t: 1u, int16_t: 1u, int32_t: 1u, default: 0u)
#define GL_MAV_HEADER(id_, type_, bits_) {.id = id_, .type = type_, .kind = GL_MAV_PARAM_HEADER, .value = bits_},
#define GL_MAV_HASH(id_) {.id = id_, .type = GL_MAV_TYPE_INT32, .kind = GL_MAV_PARAM_HASH},
#define GL_MAV_GAIN(id_, type_, member)                                                                              \
    {.id = id_,                                                                                                      \
     .type = type_,                                                                                                  \
     .kind = GL_MAV_PARAM_GAIN,                                                                                      \
     .size = (uint8_t)sizeof(GL_MAV_MEMBER(member)),                                                                 \
     .is_signed = (uint8_t)GL_MAV_SIGNED(GL_MAV_MEMBER(member)),                                                     \
     .value = (uint32_t)offsetof(gl_law_gains_t, member)},

const gl_mav_param_t gl_mav_param_table[GL_MAV_MAX_PARAMS] = {GL_LAW_PARAMS(GL_MAV_HEADER, GL_MAV_HASH, GL_MAV_GAIN)};

void gl_mav_params_init(gl_mav_params_t *table, const gl_mav_set_t *gains)
{
    memset(table, 0, sizeof *table);
    table->param = gl_mav_param_table;
    table->count = (uint16_t)GL_MAV_MAX_PARAMS;
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

float gl_mav_float_of_bits(uint32_t bits)
{
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

uint32_t gl_mav_params_bits(const gl_mav_set_t *set, const gl_mav_param_t *p)
{
    const uint8_t *at = (const uint8_t *)set + p->value;
    if (p->size == 1u) {
        return p->is_signed ? (uint32_t)(int32_t)(int8_t)at[0] : (uint32_t)at[0];
    }
    if (p->size == 2u) {
        uint16_t w;
        memcpy(&w, at, sizeof w);
        return p->is_signed ? (uint32_t)(int32_t)(int16_t)w : (uint32_t)w;
    }
    uint32_t bits;
    memcpy(&bits, at, sizeof bits);
    return bits;
}

int gl_mav_params_put_bits(gl_mav_set_t *set, const gl_mav_param_t *p, uint32_t bits)
{
    uint8_t *at = (uint8_t *)set + p->value;
    if (p->size == 4u) {
        memcpy(at, &bits, sizeof bits);
        return 0;
    }
    const int32_t v = (int32_t)bits;
    const int32_t bound = p->size == 1u ? 0x80 : 0x8000; /* the word's first value beyond its signed range */
    const int fits = p->is_signed ? (v >= -bound && v < bound) : (v >= 0 && v < 2 * bound);
    if (!fits) {
        return -1;
    }
    if (p->size == 1u) {
        at[0] = (uint8_t)v;
    } else {
        const uint16_t w = (uint16_t)v;
        memcpy(at, &w, sizeof w);
    }
    return 0;
}

float gl_mav_params_value(const gl_mav_params_t *table, uint16_t index)
{
    const gl_mav_param_t *p = &table->param[index];
    if (p->kind == GL_MAV_PARAM_HEADER) {
        return gl_mav_float_of_bits(p->value);
    }
    if (p->kind == GL_MAV_PARAM_HASH) {
        return gl_mav_float_of_bits(table->committed.crc32);
    }
    return gl_mav_float_of_bits(gl_mav_params_bits(&table->staged, p));
}

gl_status_t gl_mav_params_replace(gl_mav_params_t *table, const gl_mav_set_t *gains)
{
    static gl_law_t probe; /* large (two coefficient banks): not on the stack; the node runs from one thread */
    gl_status_t st = gl_law_init(&probe, 1u);
    if (st == GL_OK) {
        st = gl_law_stage(&probe, gains); /* every check the law makes before it runs a set */
    }
    if (st != GL_OK) {
        return st;
    }
    table->staged = *gains;
    table->committed = *gains;
    table->commits++;
    return GL_OK;
}

gl_mav_set_result_t gl_mav_params_set(gl_mav_params_t *table, uint16_t index, float value, uint8_t type)
{
    const gl_mav_param_t *p = &table->param[index];
    if (type != p->type) {
        return GL_MAV_SET_BAD_TYPE;
    }
    if (p->kind == GL_MAV_PARAM_HEADER) {
        return GL_MAV_SET_READ_ONLY;
    }
    uint32_t bits;
    memcpy(&bits, &value, sizeof bits);
    if (p->kind == GL_MAV_PARAM_HASH) { /* commit the staged values when `bits` is their CRC and they pass */
        static gl_mav_set_t candidate;  /* large: not on the stack */
        candidate = table->staged;
        candidate.crc32 = bits;
        gl_status_t st = gl_mav_params_replace(table, &candidate);
        if (st != GL_OK) {
            table->last_refusal = (int32_t)st;
            return GL_MAV_SET_BAD_VALUE;
        }
        return GL_MAV_SET_OK;
    }
    if (p->type == GL_MAV_TYPE_REAL32 && !isfinite(value)) { /* an integer's bytes may spell a NaN */
        return GL_MAV_SET_BAD_VALUE;
    }
    return gl_mav_params_put_bits(&table->staged, p, bits) == 0 ? GL_MAV_SET_OK : GL_MAV_SET_BAD_VALUE;
}
