/**
 * @file cart_pendulum_model.h
 * @brief The cart-pendulum model shared by the FMI 2.0 and FMI 3.0 FMUs (equations, Jacobian, defaults).
 *
 * States x, x_dot, theta (from upright), theta_dot; input force F on the cart. With s = sin(theta),
 * c = cos(theta), w = theta_dot and D = M + m s^2:
 *
 *     x_ddot     = (F + m l w^2 s - m g s c) / D
 *     theta_ddot = ((M + m) g s - c (F + m l w^2 s)) / (l D)
 *
 * About upright this linearises to A = [[0,1,0,0],[0,0,-m g/M,0],[0,0,0,1],[0,0,(M+m) g/(M l),0]],
 * B = [0, 1/M, 0, -1/(M l)]. Every variable is a double indexed by its value reference.
 */
#ifndef GAINLINK_CART_PENDULUM_MODEL_H
#define GAINLINK_CART_PENDULUM_MODEL_H

#define MODEL_N_REALS 14
#define MODEL_N_STATES 4
#define MODEL_STEP_VR 13

enum { VR_X = 0, VR_XD, VR_TH, VR_THD, VR_DX, VR_DXD, VR_DTH, VR_DTHD, VR_F, VR_M, VR_MP, VR_L, VR_G, VR_H };

#include <math.h>

static const unsigned int model_state_vr[MODEL_N_STATES] = {VR_X, VR_XD, VR_TH, VR_THD};
static const unsigned int model_der_vr[MODEL_N_STATES] = {VR_DX, VR_DXD, VR_DTH, VR_DTHD};

/* Start values (the glue zeroes every real first). */
static void model_set_defaults(double *r)
{
    r[VR_M] = 1.0;
    r[VR_MP] = 0.1;
    r[VR_L] = 0.5;
    r[VR_G] = 9.81;
    r[VR_H] = 0.001;
}

static void model_derivatives(double *r)
{
    const double M = r[VR_M], m = r[VR_MP], l = r[VR_L], g = r[VR_G];
    const double s = sin(r[VR_TH]), c = cos(r[VR_TH]), w = r[VR_THD], F = r[VR_F];
    const double D = M + m * s * s;
    const double f = F + m * l * w * w * s;
    r[VR_DX] = r[VR_XD];
    r[VR_DXD] = (f - m * g * s * c) / D;
    r[VR_DTH] = w;
    r[VR_DTHD] = ((M + m) * g * s - c * f) / (l * D);
}

/* Analytic partial derivative of one state derivative with respect to one state or the input. */
static int model_partial(const double *r, unsigned int unknown, unsigned int known, double *out)
{
    const double M = r[VR_M], m = r[VR_MP], l = r[VR_L], g = r[VR_G];
    const double s = sin(r[VR_TH]), c = cos(r[VR_TH]), w = r[VR_THD], F = r[VR_F];
    const double D = M + m * s * s, dD = 2.0 * m * s * c;
    const double f = F + m * l * w * w * s;
    const double n1 = f - m * g * s * c, n2 = (M + m) * g * s - c * f;
    const double dn1_th = m * l * w * w * c - m * g * (c * c - s * s);
    const double dn2_th = (M + m) * g * c + s * f - c * m * l * w * w * c;
    if (known != VR_X && known != VR_XD && known != VR_TH && known != VR_THD && known != VR_F) {
        return 0;
    }
    switch (unknown) {
    case VR_DX:
        *out = (known == VR_XD) ? 1.0 : 0.0;
        return 1;
    case VR_DTH:
        *out = (known == VR_THD) ? 1.0 : 0.0;
        return 1;
    case VR_DXD:
        switch (known) {
        case VR_TH: *out = (dn1_th * D - n1 * dD) / (D * D); break;
        case VR_THD: *out = 2.0 * m * l * w * s / D; break;
        case VR_F: *out = 1.0 / D; break;
        default: *out = 0.0; break;
        }
        return 1;
    case VR_DTHD:
        switch (known) {
        case VR_TH: *out = (dn2_th * D - n2 * dD) / (l * D * D); break;
        case VR_THD: *out = -c * 2.0 * m * l * w * s / (l * D); break;
        case VR_F: *out = -c / (l * D); break;
        default: *out = 0.0; break;
        }
        return 1;
    default:
        return 0;
    }
}

#endif /* GAINLINK_CART_PENDULUM_MODEL_H */
