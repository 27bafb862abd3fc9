/**
 * @file gl_mav_table.c
 * @brief What the three parameter tables (float32 gl_mav_params.c, fixed point gl_mav_fxparams.c, scheduled
 *        gl_mav_schedparams.c) do alike: find a parameter by id, stage a value, and commit the staged set when
 *        GL_HASH is set to its CRC-32, through the law's own checks (its gl_mav_params_replace).
 */
#include "gl_mav_params.h"

#include <math.h>
#include <string.h>

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

gl_mav_set_result_t gl_mav_params_set(gl_mav_params_t *table, uint16_t index, float value, uint8_t type)
{
    const gl_mav_param_t *p = &table->param[index];
    if (type != p->type) {
        return GL_MAV_SET_BAD_TYPE;
    }
    if (p->header >= 0 && p->header != GL_MAV_HASH_HEADER) {
        return GL_MAV_SET_READ_ONLY;
    }
    uint32_t bits;
    memcpy(&bits, &value, sizeof bits);
    if (p->header == GL_MAV_HASH_HEADER) { /* commit the staged values when `bits` is their CRC and they pass */
        static gl_mav_set_t candidate;     /* large (fixed point, scheduled): not on the stack */
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
    gl_mav_params_put_bits(&table->staged, p->offset, bits);
    return GL_MAV_SET_OK;
}
