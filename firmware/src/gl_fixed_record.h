/**
 * @file gl_fixed_record.h
 * @brief One step of the fixed-point loop as the record the host library and the image's replay write
 *        (gainlink.firmware.fixed reads both the same way).
 *
 * Record (little-endian, all 32-bit): flags, sat_mask, clip_mask, overflow_mask, U[GL_FX_M] (command words),
 * V[GL_FX_M], XH[GL_FX_N], Z[GL_FX_QA], u[GL_FX_M] (the float commands).
 */
#ifndef GAINLINK_GL_FIXED_RECORD_H
#define GAINLINK_GL_FIXED_RECORD_H

#include <string.h>

#include "gainlink/gl_fixed.h"

#define GL_FX_RECORD_WORDS (4 + 3 * GL_FX_M + GL_FX_N + GL_FX_QA)

typedef struct {
    uint32_t flags;
    uint32_t sat_mask;
    uint32_t clip_mask;
    uint32_t overflow_mask;
    int32_t U[GL_FX_M];
    int32_t V[GL_FX_M];
    int32_t XH[GL_FX_N];
    int32_t Z[GL_FX_QA];
    float u[GL_FX_M];
} gl_fixed_record_t;

_Static_assert(sizeof(gl_fixed_record_t) == 4u * GL_FX_RECORD_WORDS, "gl_fixed_record_t must be packed");

/** @brief Fill `o` from the loop after a step that returned the float commands `u`. */
static inline void gl_fixed_record(const gl_fixed_loop_t *loop, const float *u, gl_fixed_record_t *o)
{
    o->flags = loop->flags;
    o->sat_mask = loop->sat_mask;
    o->clip_mask = loop->clip_mask;
    o->overflow_mask = loop->overflow_mask;
    for (unsigned i = 0; i < GL_FX_M; ++i) {
        o->U[i] = loop->u[i];
        o->V[i] = loop->v[i];
        o->u[i] = u[i];
    }
    memcpy(o->XH, &loop->sig[GL_FX_SIG_XH], sizeof o->XH);
    memset(o->Z, 0, sizeof o->Z);
#if GL_FX_Q > 0
    memcpy(o->Z, &loop->sig[GL_FX_SIG_Z], sizeof(int32_t) * GL_FX_Q);
#endif
}

#endif /* GAINLINK_GL_FIXED_RECORD_H */
