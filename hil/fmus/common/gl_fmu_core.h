/**
 * @file gl_fmu_core.h
 * @brief What the FMI 2.0 and FMI 3.0 glue of gainlink's plant FMUs share: the model's reals, its right-hand side,
 *        the Co-Simulation step (RK4 sub-steps) and the directional derivatives. No FMI type appears here.
 *
 * A model source defines, before including a glue file (fmi2_glue.c or fmi3_glue.c), which includes this one:
 *  - MODEL_N_REALS, MODEL_N_STATES and MODEL_STEP_VR (value reference of the largest internal RK4 step; a
 *    Model-Exchange-only model may leave it out),
 *  - model_state_vr[] / model_der_vr[] (unsigned int: value references of the states and of their derivatives),
 *  - model_set_defaults(double *r): start values of every real (gl_core_zero clears them first),
 *  - model_derivatives(double *r): fill the derivative reals from states, inputs and parameters,
 *  - model_partial(const double *r, unsigned int unknown, unsigned int known, double *out): one Jacobian entry of
 *    a derivative with respect to a state or an input; returns 0 when the pair is not supported.
 * Optionally GL_FMU_CONSTRAINTS and model_constrain(double *r): state constraints (e.g. a ground contact) applied
 * after every internal RK4 step of a Co-Simulation step (Model Exchange solvers integrate the unconstrained
 * derivatives). A Co-Simulation-only model (GL_FMU_CS_ONLY, FMI 2.0 only; see fmi2_glue.c) defines only the
 * reals, the defaults and model_derivatives (its outputs from its state), and uses none of the state functions
 * below.
 *
 * Every variable is a double in one array indexed by value reference.
 */
#ifndef GAINLINK_FMU_CORE_H
#define GAINLINK_FMU_CORE_H

#include <math.h>
#include <stddef.h>

/* All reals to zero: models then set only the start values that are not. */
static inline void gl_core_zero(double *r)
{
    for (size_t i = 0; i < MODEL_N_REALS; i++) {
        r[i] = 0.0;
    }
}

/* Copy n values out of / into the reals; returns 0, or -1 when a value reference is unknown. */
static int gl_core_get(const double *r, const unsigned int vr[], size_t n, double value[])
{
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= MODEL_N_REALS) {
            return -1;
        }
        value[i] = r[vr[i]];
    }
    return 0;
}

static int gl_core_set(double *r, const unsigned int vr[], size_t n, const double value[])
{
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= MODEL_N_REALS) {
            return -1;
        }
        r[vr[i]] = value[i];
    }
    model_derivatives(r);
    return 0;
}

#ifndef GL_FMU_CS_ONLY
/* The continuous states and their derivatives, in model_state_vr order. */
static void gl_core_get_states(const double *r, double *x)
{
    for (size_t i = 0; i < MODEL_N_STATES; i++) {
        x[i] = r[model_state_vr[i]];
    }
}

static void gl_core_set_states(double *r, const double *x)
{
    for (size_t i = 0; i < MODEL_N_STATES; i++) {
        r[model_state_vr[i]] = x[i];
    }
    model_derivatives(r);
}

static void gl_core_get_derivatives(double *r, double *dx)
{
    model_derivatives(r);
    for (size_t i = 0; i < MODEL_N_STATES; i++) {
        dx[i] = r[model_der_vr[i]];
    }
}

/* dx = f(x) with the other reals as they are; the states are left unchanged. */
static void gl_core_rhs(double *r, const double *x, double *dx)
{
    double keep[MODEL_N_STATES];
    gl_core_get_states(r, keep);
    for (size_t i = 0; i < MODEL_N_STATES; i++) {
        r[model_state_vr[i]] = x[i];
    }
    gl_core_get_derivatives(r, dx);
    for (size_t i = 0; i < MODEL_N_STATES; i++) {
        r[model_state_vr[i]] = keep[i];
    }
}

/* One classical RK4 step of length h from the current states. */
static void gl_core_rk4(double *r, double h)
{
    double x[MODEL_N_STATES], k1[MODEL_N_STATES], k2[MODEL_N_STATES], k3[MODEL_N_STATES], k4[MODEL_N_STATES];
    double t[MODEL_N_STATES];
    gl_core_get_states(r, x);
    gl_core_rhs(r, x, k1);
    for (size_t i = 0; i < MODEL_N_STATES; i++) { t[i] = x[i] + 0.5 * h * k1[i]; }
    gl_core_rhs(r, t, k2);
    for (size_t i = 0; i < MODEL_N_STATES; i++) { t[i] = x[i] + 0.5 * h * k2[i]; }
    gl_core_rhs(r, t, k3);
    for (size_t i = 0; i < MODEL_N_STATES; i++) { t[i] = x[i] + h * k3[i]; }
    gl_core_rhs(r, t, k4);
    for (size_t i = 0; i < MODEL_N_STATES; i++) {
        t[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
    gl_core_set_states(r, t);
}

/* One communication step of length h: RK4 sub-steps no longer than r[MODEL_STEP_VR] (h itself when that is
 * not positive), each followed by the model's constraints. Returns NULL, or the reason it failed. */
static const char *gl_core_do_step(double *r, double h)
{
    if (!(h >= 0.0)) {
        return "negative communication step";
    }
#ifdef MODEL_STEP_VR
    double hmax = r[MODEL_STEP_VR];
#else
    double hmax = 0.0; /* a Model-Exchange-only model has no internal step of its own */
#endif
    if (!(hmax > 0.0)) {
        hmax = h;
    }
    long n = (long)ceil(h / hmax - 1e-9);
    if (n < 1) {
        n = 1;
    }
    for (long k = 0; k < n; k++) {
        gl_core_rk4(r, h / (double)n);
#ifdef GL_FMU_CONSTRAINTS
        model_constrain(r);
        model_derivatives(r);
#endif
    }
    for (size_t i = 0; i < MODEL_N_STATES; i++) {
        if (!isfinite(r[model_state_vr[i]])) {
            return "state became non-finite";
        }
    }
    return NULL;
}

/* Directional derivatives at the current reals: out_i = sum_j d unknown_i / d known_j * seed_j. An unknown that is
 * a state has the identity as its partials. Returns NULL, or the reason it failed. */
static const char *gl_core_directional(const double *r, const unsigned int unknown[], size_t n_unknown,
                                       const unsigned int known[], size_t n_known, const double seed[], double out[])
{
    for (size_t i = 0; i < n_unknown; i++) {
        int is_state = 0;
        for (size_t s = 0; s < MODEL_N_STATES; s++) {
            is_state |= unknown[i] == model_state_vr[s];
        }
        double acc = 0.0;
        for (size_t j = 0; j < n_known; j++) {
            double d = 0.0;
            if (is_state) {
                d = unknown[i] == known[j] ? 1.0 : 0.0;
            } else if (!model_partial(r, unknown[i], known[j], &d)) {
                return "unsupported variable pair";
            }
            acc += d * seed[j];
        }
        out[i] = acc;
    }
    return NULL;
}
#endif /* GL_FMU_CS_ONLY */

#endif /* GAINLINK_FMU_CORE_H */
