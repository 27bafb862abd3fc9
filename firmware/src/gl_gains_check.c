/**
 * @file gl_gains_check.c
 * @brief Gain-set checksum, validation and derivation of the step coefficients (double precision).
 */
#include <math.h>
#include <stddef.h>
#include <string.h>

#include "gl_internal.h"
#include "gainlink/gl_crc32.h"

/* The field lists below (GL_GAINS_STRUCTURE, GL_GAINS_FLOATS from Ts on) come from gl_gains_layout.h, generated
 * from the field table gainlink.shipping.gains_layout. */
#define GL_STRUCTURE_WORD(field, compiled, param) gains->field,
#define GL_STRUCTURE_DIFFERS(field, compiled, param) || gains->field != (uint32_t)(compiled)

uint32_t gl_gains_crc32(const gl_gains_t *gains)
{
    if (gains == NULL) {
        return 0u;
    }
    uint32_t crc = 0xFFFFFFFFu;
    const uint32_t header[GL_GAINS_STRUCTURE_FIELDS] = {GL_GAINS_STRUCTURE(GL_STRUCTURE_WORD)};
    for (size_t i = 0; i < GL_GAINS_STRUCTURE_FIELDS; ++i) {
        crc = gl_crc32_word(crc, header[i]);
    }
    const float *payload = &gains->Ts;
    for (size_t i = 0; i < (size_t)(GL_GAINS_FLOATS); ++i) {
        uint32_t bits;
        memcpy(&bits, &payload[i], sizeof bits);
        crc = gl_crc32_word(crc, bits); /* little-endian bytes, whatever the host */
    }
    return crc ^ 0xFFFFFFFFu;
}

gl_status_t gl_gains_check(const gl_gains_t *gains)
{
    if (gains == NULL) {
        return GL_ERR_NULL;
    }
    if (0 GL_GAINS_STRUCTURE(GL_STRUCTURE_DIFFERS)) {
        return GL_ERR_DIMS;
    }
    if (gains->crc32 != gl_gains_crc32(gains)) {
        return GL_ERR_CRC;
    }
    const float *payload = &gains->Ts;
    for (size_t i = 0; i < (size_t)(GL_GAINS_FLOATS); ++i) {
        if (!isfinite(payload[i])) {
            return GL_ERR_NANINF;
        }
    }
    if (!(gains->Ts > 0.0f)) {
        return GL_ERR_RANGE;
    }
    for (size_t k = 0; k < GL_M; ++k) {
        if (gains->u_min[k] > gains->u_max[k]) {
            return GL_ERR_RANGE;
        }
    }
    return GL_OK;
}

/** Round a double to float and report whether it stayed finite. */
static int store_finite(float *dst, double value)
{
    *dst = (float)value;
    return isfinite(*dst);
}

/**
 * Command rows: u_op, then the feedback stored negated so that v - u_op is a plain sum of products
 * (Kx = K (I - M Cd), Ky = K M in the current form), Ki, the limits; and the safe command u_op clamped.
 * Returns the stream position after them; clears `*ok` when a derived coefficient is not finite in float.
 */
static float *derive_command_rows(const gl_gains_t *g, gl_coeffs_t *c, float *w, int *ok)
{
    for (size_t i = 0; i < GL_M; ++i) {
        *w++ = g->u_op[i];
        double KMrow[GL_P];
        for (size_t k = 0; k < GL_P; ++k) {
            double acc = 0.0;
#if GL_OBSERVER_FORM == GL_FORM_CURRENT
            for (size_t l = 0; l < GL_N; ++l) {
                acc += (double)g->K[i][l] * (double)g->M[l][k];
            }
#endif
            KMrow[k] = acc;
        }
        for (size_t j = 0; j < GL_N; ++j) { /* Kx = K (I - M Cd) = K - (K M) Cd */
            double acc = (double)g->K[i][j];
            for (size_t k = 0; k < GL_P; ++k) {
                acc -= KMrow[k] * (double)g->Cd[k][j];
            }
            *ok &= store_finite(w++, -acc);
        }
#if GL_OBSERVER_FORM == GL_FORM_CURRENT
        for (size_t k = 0; k < GL_P; ++k) {
            *ok &= store_finite(w++, -KMrow[k]);
        }
#endif
        for (int j = 0; j < GL_Q; ++j) {
            *w++ = -g->Ki[i][j];
        }
        *w++ = g->u_min[i];
        *w++ = g->u_max[i];
        float safe = g->u_op[i];
        safe = safe < g->u_min[i] ? g->u_min[i] : safe;
        safe = safe > g->u_max[i] ? g->u_max[i] : safe;
        c->u_safe[i] = safe;
    }
    return w;
}

/** Integrator rows: e = r + sum(-Ci y), z += Ts e [+ Kaw (u - v)]. Returns the stream position after them. */
static float *derive_integrator_rows(const gl_gains_t *g, float *w)
{
    for (int j = 0; j < GL_Q; ++j) {
        for (size_t k = 0; k < GL_P; ++k) {
            *w++ = -g->Ci[j][k];
        }
        *w++ = g->Ts;
#if GL_ANTI_WINDUP == GL_AW_BACKCALC
        for (size_t k = 0; k < GL_M; ++k) {
            *w++ = g->Kaw[j][k];
        }
#endif
    }
    (void)g; /* without integral action there are no rows */
    return w;
}

/**
 * Estimate rows: F = Ad - L Cd, G = Bd - L Dd, L (current form: L = Ad M, docs/design.md "The control law"),
 * in double, rounded once.
 * Returns the stream position after them; clears `*ok` when a derived coefficient is not finite in float.
 */
static float *derive_estimate_rows(const gl_gains_t *g, float *w, int *ok)
{
    for (size_t i = 0; i < GL_N; ++i) {
        double Lrow[GL_P];
        for (size_t k = 0; k < GL_P; ++k) {
            double acc = (double)g->L[i][k];
#if GL_OBSERVER_FORM == GL_FORM_CURRENT
            acc = 0.0;
            for (size_t l = 0; l < GL_N; ++l) {
                acc += (double)g->Ad[i][l] * (double)g->M[l][k];
            }
#endif
            Lrow[k] = acc;
        }
        for (size_t j = 0; j < GL_N; ++j) {
            double acc = (double)g->Ad[i][j];
            for (size_t k = 0; k < GL_P; ++k) {
                acc -= Lrow[k] * (double)g->Cd[k][j];
            }
            *ok &= store_finite(w++, acc);
        }
        for (size_t j = 0; j < GL_M; ++j) {
            double acc = (double)g->Bd[i][j];
            for (size_t k = 0; k < GL_P; ++k) {
                acc -= Lrow[k] * (double)g->Dd[k][j];
            }
            *ok &= store_finite(w++, acc);
        }
        for (size_t k = 0; k < GL_P; ++k) {
            *ok &= store_finite(w++, Lrow[k]);
        }
    }
    return w;
}

gl_status_t gl_coeffs_derive(const gl_gains_t *g, gl_coeffs_t *c)
{
    gl_status_t st = gl_gains_check(g);
    if (st != GL_OK) {
        return st;
    }
    int ok = 1;
    float *w = c->w;
    memset(c->w, 0, sizeof c->w);
    /* The measurement's operating point, subtracted from y first (dy = y - y_op). */
    for (size_t k = 0; k < GL_P; ++k) {
        *w++ = g->y_op[k];
    }
    w = derive_command_rows(g, c, w, &ok);
    w = derive_integrator_rows(g, w);
    (void)derive_estimate_rows(g, w, &ok);
    for (size_t i = 0; i < GL_N; ++i) {
        c->xh0[i] = g->xh0[i];
    }
    for (size_t j = 0; j < GL_QA; ++j) {
        c->z0[j] = g->z0[j];
    }
    c->crc32 = g->crc32;
    return ok ? GL_OK : GL_ERR_NANINF;
}
