/**
 * @file mass_spring_damper3.c
 * @brief A mass on a linear spring and damper pushed by a force, FMI 3.0 Model Exchange only.
 *
 * States s (position), v (velocity); input f (force); output s. With mass m, stiffness c, damping d and the
 * position s0 where the spring is unloaded:
 *
 *     s_dot = v,  v_dot = (f - c (s - s0) - d v) / m
 *
 * Linear everywhere: A = [[0, 1], [-c/m, -d/m]], B = [0, 1/m], C = [1, 0]; at rest with f = 0, s = s0. The
 * defaults (m 2 kg, c 50 N/m, d 3 N s/m) give w_n = 5 rad/s and a damping ratio of 0.15.
 */
#define MODEL_TOKEN "{6a1f2c3d-4e5b-4c7a-9d8e-0f1a2b3c4d5e}"
#define MODEL_N_REALS 9
#define MODEL_N_STATES 2
#define GL_FMU_ME_ONLY 1

enum { VR_S = 0, VR_V, VR_DS, VR_DV, VR_F, VR_MASS, VR_C, VR_D, VR_S0 };

static const unsigned int model_state_vr[MODEL_N_STATES] = {VR_S, VR_V};
static const unsigned int model_der_vr[MODEL_N_STATES] = {VR_DS, VR_DV};

/* Start values (the glue zeroes every real first). */
static void model_set_defaults(double *r)
{
    r[VR_S] = 0.5;
    r[VR_MASS] = 2.0;
    r[VR_C] = 50.0;
    r[VR_D] = 3.0;
    r[VR_S0] = 0.5;
}

static void model_derivatives(double *r)
{
    r[VR_DS] = r[VR_V];
    r[VR_DV] = (r[VR_F] - r[VR_C] * (r[VR_S] - r[VR_S0]) - r[VR_D] * r[VR_V]) / r[VR_MASS];
}

/* Analytic partial derivative of one state derivative with respect to one state or the input. */
static int model_partial(const double *r, unsigned int unknown, unsigned int known, double *out)
{
    if (known != VR_S && known != VR_V && known != VR_F) {
        return 0;
    }
    switch (unknown) {
    case VR_DS: *out = known == VR_V ? 1.0 : 0.0; return 1;
    case VR_DV:
        *out = known == VR_S ? -r[VR_C] / r[VR_MASS] : known == VR_V ? -r[VR_D] / r[VR_MASS] : 1.0 / r[VR_MASS];
        return 1;
    default: return 0;
    }
}

#include "fmi3_glue.c"
