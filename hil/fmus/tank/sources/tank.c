/**
 * @file tank.c
 * @brief A tank drained through an orifice and filled by a pump with a first-order lag; FMI 2.0 (ME + CS).
 *
 * The equations of gainlink's built-in `tank` plant (hil/plants/tank.py): pump flow q, level h, pump command u,
 *
 *     dq/dt = (u - q) / tau_p,    dh/dt = (q - c sqrt(h+)) / (area + flare h+),    h+ = max(h, 0),
 *
 * the cross-section growing with the level (flare = 0: a cylinder of section `area`). The orifice passes nothing
 * below empty, and in Co-Simulation a level below 0 is clipped to 0 after every internal step. At a level h0 the
 * trim is q = u = c sqrt(h0), where the linearisation is dq/dt = (u - q) / tau_p,
 * dh/dt = (q - c / (2 sqrt(h0)) h) / (area + flare h0): the level's time constant 2 sqrt(h0) (area + flare h0) / c.
 */
#define MODEL_GUID "{3f7b2d10-6c4a-4e8b-9a51-2d7e0c9b5a18}"
#define MODEL_N_REALS 10
#define MODEL_N_STATES 2
#define MODEL_STEP_VR 9
#define GL_FMU_CONSTRAINTS 1

enum { VR_H = 0, VR_Q, VR_DH, VR_DQ, VR_U, VR_C, VR_TAU, VR_AREA, VR_FLARE, VR_STEP };

#include <math.h>

/* States in the order of the example specs: q, h. */
static const unsigned int model_state_vr[MODEL_N_STATES] = {VR_Q, VR_H};
static const unsigned int model_der_vr[MODEL_N_STATES] = {VR_DQ, VR_DH};

/* Start values (the glue zeroes every real first): at rest at 4 cm. */
static void model_set_defaults(double *r)
{
    r[VR_H] = 0.04;
    r[VR_Q] = 0.08;
    r[VR_U] = 0.08;
    r[VR_C] = 0.4;
    r[VR_TAU] = 0.1;
    r[VR_AREA] = 1.0;
    r[VR_STEP] = 0.001;
}

static double level(const double *r) { return r[VR_H] > 0.0 ? r[VR_H] : 0.0; }

static double section(const double *r) { return r[VR_AREA] + r[VR_FLARE] * level(r); }

static void model_derivatives(double *r)
{
    r[VR_DQ] = (r[VR_U] - r[VR_Q]) / r[VR_TAU];
    r[VR_DH] = (r[VR_Q] - r[VR_C] * sqrt(level(r))) / section(r);
}

/* The bottom: no level below empty. */
static void model_constrain(double *r)
{
    if (r[VR_H] < 0.0) {
        r[VR_H] = 0.0;
    }
}

/* d(dh/dt)/dh for h > 0 (the orifice's term and the section's); 0 below empty, where nothing depends on h. */
static double dlevel_dh(const double *r)
{
    const double h = level(r);
    if (!(h > 0.0)) {
        return 0.0;
    }
    const double a = section(r);
    const double net = r[VR_Q] - r[VR_C] * sqrt(h);
    return -r[VR_C] / (2.0 * sqrt(h)) / a - net * r[VR_FLARE] / (a * a);
}

/* Analytic partial derivative of one state derivative with respect to one state or the input. */
static int model_partial(const double *r, unsigned int unknown, unsigned int known, double *out)
{
    if (known != VR_H && known != VR_Q && known != VR_U) {
        return 0;
    }
    *out = 0.0;
    switch (unknown) {
    case VR_DQ:
        if (known == VR_Q) {
            *out = -1.0 / r[VR_TAU];
        } else if (known == VR_U) {
            *out = 1.0 / r[VR_TAU];
        }
        return 1;
    case VR_DH:
        if (known == VR_Q) {
            *out = 1.0 / section(r);
        } else if (known == VR_H) {
            *out = dlevel_dh(r);
        }
        return 1;
    default: return 0;
    }
}

#include "fmi2_glue.c"
