/**
 * @file multirotor_vertical.c
 * @brief Vertical channel of a multirotor: throttle in, altitude out, hover at a non-zero trim; FMI 2.0 (ME + CS).
 *
 * States z (altitude above the ground), w (vertical speed); input throttle u in [0, 1]; rotor thrust k_T u^2
 * (thrust grows with the square of rotor speed), quadratic air drag:
 *
 *     z_dot = w,  w_dot = k_T u^2 / mass - g - (c_d / mass) w |w|
 *
 * Hover (the trim) at any altitude: w = 0, u = sqrt(mass g / k_T) (0.7004 with the defaults), where the
 * linearisation is A = [[0, 1], [0, 0]], B = [0, 2 k_T u / mass]. The ground is a contact: in Co-Simulation
 * the altitude never goes below 0 (after each internal step, z < 0 becomes 0 and a downward speed there
 * becomes 0), so a vehicle whose thrust is below its weight rests on the ground.
 */
#define MODEL_GUID "{8d3c1f52-2b7e-4a61-9c0e-6f4a7d1b2c03}"
#define MODEL_N_REALS 10
#define MODEL_N_STATES 2
#define MODEL_STEP_VR 9
#define GL_FMU_CONSTRAINTS 1

enum { VR_Z = 0, VR_W, VR_DZ, VR_DW, VR_U, VR_MASS, VR_G, VR_KT, VR_CD, VR_H };

#include <math.h>

static const unsigned int model_state_vr[MODEL_N_STATES] = {VR_Z, VR_W};
static const unsigned int model_der_vr[MODEL_N_STATES] = {VR_DZ, VR_DW};

/* Start values (the glue zeroes every real first). */
static void model_set_defaults(double *r)
{
    r[VR_Z] = 2.0;
    r[VR_MASS] = 1.5;
    r[VR_G] = 9.81;
    r[VR_KT] = 30.0;
    r[VR_CD] = 0.05;
    r[VR_H] = 0.001;
}

static void model_derivatives(double *r)
{
    const double u = r[VR_U], w = r[VR_W], mass = r[VR_MASS];
    r[VR_DZ] = w;
    r[VR_DW] = r[VR_KT] * u * u / mass - r[VR_G] - r[VR_CD] / mass * w * fabs(w);
}

/* The ground: no altitude below 0, no downward speed on it. */
static void model_constrain(double *r)
{
    if (r[VR_Z] < 0.0) {
        r[VR_Z] = 0.0;
    }
    if (r[VR_Z] == 0.0 && r[VR_W] < 0.0) {
        r[VR_W] = 0.0;
    }
}

/* Analytic partial derivative of one state derivative with respect to one state or the input. */
static int model_partial(const double *r, unsigned int unknown, unsigned int known, double *out)
{
    if (known != VR_Z && known != VR_W && known != VR_U) {
        return 0;
    }
    *out = 0.0;
    switch (unknown) {
    case VR_DZ: *out = known == VR_W ? 1.0 : 0.0; return 1;
    case VR_DW:
        if (known == VR_W) {
            *out = -2.0 * r[VR_CD] / r[VR_MASS] * fabs(r[VR_W]);
        } else if (known == VR_U) {
            *out = 2.0 * r[VR_KT] * r[VR_U] / r[VR_MASS];
        }
        return 1;
    default: return 0;
    }
}

#include "fmi2_glue.c"
