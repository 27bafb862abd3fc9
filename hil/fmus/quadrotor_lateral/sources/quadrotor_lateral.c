/**
 * @file quadrotor_lateral.c
 * @brief Quadrotor lateral channel holding altitude, FMI 2.0 (ME + CS).
 *
 * States phi (roll), p (roll rate), v (lateral speed), y (lateral position); input roll torque tau:
 *
 *     phi_dot = p,  p_dot = tau / Ixx,  v_dot = g tan(phi) - (c_d / mass) v,  y_dot = v
 *
 * About hover (c_d = 0): A = [[0,1,0,0],[0,0,0,0],[g,0,0,0],[0,0,1,0]], B = [0, 1/Ixx, 0, 0].
 */
#define MODEL_GUID "{5f0b6a1e-7c1d-4c55-9a57-3e2b1f0c0a02}"
#define MODEL_N_REALS 14
#define MODEL_N_STATES 4
#define MODEL_STEP_VR 13

enum { VR_PHI = 0, VR_P, VR_V, VR_Y, VR_DPHI, VR_DP, VR_DV, VR_DY, VR_TAU, VR_G, VR_IXX, VR_MASS, VR_CD, VR_H };

#include <math.h>

static const unsigned int model_state_vr[MODEL_N_STATES] = {VR_PHI, VR_P, VR_V, VR_Y};
static const unsigned int model_der_vr[MODEL_N_STATES] = {VR_DPHI, VR_DP, VR_DV, VR_DY};

/* Start values (the glue zeroes every real first). */
static void model_set_defaults(double *r)
{
    r[VR_G] = 9.81;
    r[VR_IXX] = 0.01;
    r[VR_MASS] = 1.0;
    r[VR_CD] = 0.0;
    r[VR_H] = 0.001;
}

static void model_derivatives(double *r)
{
    r[VR_DPHI] = r[VR_P];
    r[VR_DP] = r[VR_TAU] / r[VR_IXX];
    r[VR_DV] = r[VR_G] * tan(r[VR_PHI]) - r[VR_CD] / r[VR_MASS] * r[VR_V];
    r[VR_DY] = r[VR_V];
}

/* Analytic partial derivative of one state derivative with respect to one state or the input. */
static int model_partial(const double *r, unsigned int unknown, unsigned int known, double *out)
{
    if (known != VR_PHI && known != VR_P && known != VR_V && known != VR_Y && known != VR_TAU) {
        return 0;
    }
    const double c = cos(r[VR_PHI]);
    *out = 0.0;
    switch (unknown) {
    case VR_DPHI: *out = known == VR_P ? 1.0 : 0.0; return 1;
    case VR_DP: *out = known == VR_TAU ? 1.0 / r[VR_IXX] : 0.0; return 1;
    case VR_DV:
        if (known == VR_PHI) {
            *out = r[VR_G] / (c * c);
        } else if (known == VR_V) {
            *out = -r[VR_CD] / r[VR_MASS];
        }
        return 1;
    case VR_DY: *out = known == VR_V ? 1.0 : 0.0; return 1;
    default: return 0;
    }
}

#include "fmi2_glue.c"
