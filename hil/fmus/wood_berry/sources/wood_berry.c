/**
 * @file wood_berry.c
 * @brief Wood-Berry distillation column with exact dead times, FMI 2.0 Co-Simulation only.
 *
 * Time in minutes. Four first-order lags with pure input delays (Wood & Berry 1973):
 *
 *     x_D = y11 + y12,  x_B = y21 + y22,
 *     tau_ij dy_ij/dt = -y_ij + K_ij u_j(t - theta_ij),   u = (reflux, steam),
 *     K = [[12.8, -18.9], [6.6, -19.4]], tau = [[16.7, 21.0], [10.9, 14.4]], theta = [[1, 3], [7, 3]],
 *
 * the same model as gainlink.hil.plants.models.WoodBerry, with the same variable names.
 *
 * Why Co-Simulation only: with dead times, a Model Exchange FMU would have to announce a time event
 * at every instant an input change reaches a lag (t_input + theta_ij) and keep a time-stamped input
 * history for the solver; the bridge only runs Co-Simulation, so this FMU does not offer it.
 *
 * Scheme (exact for a zero-order-hold input): the communication step h is fixed by the first
 * fmi2DoStep and must divide every dead time, theta_ij = d_ij h. The inputs set before each step are
 * held over it and kept, one sample per step, in a fixed ring buffer per input inside the instance
 * (WB_DELAY_CAPACITY samples, so d_ij <= WB_DELAY_CAPACITY); lag ij then sees the sample of d_ij
 * steps earlier (zero before the start: deviation variables) and is advanced by its exact ZOH
 * discretisation y <- a y + (1 - a) K u, a = exp(-h / tau). A step that does not divide a dead
 * time, a longer delay than the ring holds, or a later step of another length is refused with
 * fmi2Error and a logged message. The rings are part of the FMU state (fmi2GetFMUstate).
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#define GL_FMU_CS_ONLY
#define MODEL_GUID "{380e5fca-5fa8-4fb8-bb04-024f4b6a9310}"
#define MODEL_N_REALS 28
/** Input samples each delay line holds: a dead time may be at most this many communication steps. */
#define WB_DELAY_CAPACITY 1024

enum {
    VR_REFLUX = 0, VR_STEAM, VR_XD, VR_XB,
    VR_Y11, VR_Y12, VR_Y21, VR_Y22,
    VR_DY11, VR_DY12, VR_DY21, VR_DY22,
    VR_K11, VR_K12, VR_K21, VR_K22,
    VR_TAU11, VR_TAU12, VR_TAU21, VR_TAU22,
    VR_THETA11, VR_THETA12, VR_THETA21, VR_THETA22,
    VR_SEEN11, VR_SEEN12, VR_SEEN21, VR_SEEN22
};

/* Offsets of lag ij (i output, j input) from the first reference of each group: 2 i + j. */
#define WB_LAG(i, j) (2 * (i) + (j))

typedef struct {
    double past[2][WB_DELAY_CAPACITY]; /* input j of communication step s (s >= 1) at past[j][s % capacity] */
    long long steps;                   /* communication steps taken since instantiation or reset */
    double h;                          /* communication step fixed by the first fmi2DoStep; 0 before */
    long delay[2][2];                  /* dead times in communication steps, fixed with h */
} model_extra_t;

static const char *const wb_lag_name[4] = {"11 (reflux -> x_D)", "12 (steam -> x_D)", "21 (reflux -> x_B)",
                                           "22 (steam -> x_B)"};

/* Start values (the glue zeroes every real first). */
static void model_set_defaults(double *r)
{
    static const double K[4] = {12.8, -18.9, 6.6, -19.4};
    static const double tau[4] = {16.7, 21.0, 10.9, 14.4};
    static const double theta[4] = {1.0, 3.0, 7.0, 3.0};
    for (int l = 0; l < 4; l++) {
        r[VR_K11 + l] = K[l];
        r[VR_TAU11 + l] = tau[l];
        r[VR_THETA11 + l] = theta[l];
    }
}

/* Outputs and derivatives from the lags and the delayed inputs they see over the next step. */
static void model_derivatives(double *r)
{
    for (int i = 0; i < 2; i++) {
        for (int j = 0; j < 2; j++) {
            const int l = WB_LAG(i, j);
            const double u = r[VR_THETA11 + l] > 0.0 ? r[VR_SEEN11 + l] : r[VR_REFLUX + j];
            r[VR_DY11 + l] = (r[VR_K11 + l] * u - r[VR_Y11 + l]) / r[VR_TAU11 + l];
        }
    }
    r[VR_XD] = r[VR_Y11] + r[VR_Y12];
    r[VR_XB] = r[VR_Y21] + r[VR_Y22];
}

static void model_extra_reset(model_extra_t *x)
{
    memset(x, 0, sizeof *x);
}

/* Input j as it was set for communication step s (zero before the first step). */
static double wb_past(const model_extra_t *x, int j, long long s)
{
    return s >= 1 ? x->past[j][s % WB_DELAY_CAPACITY] : 0.0;
}

/* Fix the communication step h: every dead time must be a whole number of steps that the ring holds. */
static int wb_fix_step(const double *r, model_extra_t *x, double h, char *msg, size_t msg_size)
{
    long delay[2][2];
    int longest = 0;
    for (int l = 0; l < 4; l++) {
        const double tau = r[VR_TAU11 + l], theta = r[VR_THETA11 + l];
        if (!(tau > 0.0) || !isfinite(tau) || !(theta >= 0.0) || !isfinite(theta)) {
            snprintf(msg, msg_size, "fmi2DoStep: lag %s needs tau > 0 and theta >= 0 (tau = %g, theta = %g min)",
                     wb_lag_name[l], tau, theta);
            return 1;
        }
        const double q = theta / h;
        const double n = nearbyint(q);
        if (fabs(q - n) > 1e-9 * fmax(1.0, q)) {
            snprintf(msg, msg_size, "fmi2DoStep: communication step %g min does not divide the dead time "
                     "theta%.2s = %g min of lag %s (%.6g steps); use a step that divides every dead time",
                     h, wb_lag_name[l], theta, wb_lag_name[l], q);
            return 1;
        }
        longest = theta > r[VR_THETA11 + longest] ? l : longest;
    }
    const double theta_max = r[VR_THETA11 + longest];
    if (nearbyint(theta_max / h) > (double)WB_DELAY_CAPACITY) {
        snprintf(msg, msg_size, "fmi2DoStep: dead time theta%.2s = %g min is %.0f communication steps of %g min; "
                 "the delay lines hold %d (use a step >= %g min)", wb_lag_name[longest], theta_max,
                 nearbyint(theta_max / h), h, WB_DELAY_CAPACITY, theta_max / WB_DELAY_CAPACITY);
        return 1;
    }
    for (int l = 0; l < 4; l++) {
        delay[l / 2][l % 2] = (long)nearbyint(r[VR_THETA11 + l] / h);
    }
    memcpy(x->delay, delay, sizeof delay);
    x->h = h;
    return 0;
}

static int model_do_step(double *r, model_extra_t *x, double h, char *msg, size_t msg_size)
{
    if (!(h > 0.0) || !isfinite(h)) {
        snprintf(msg, msg_size, "fmi2DoStep: the communication step must be positive (got %g min)", h);
        return 1;
    }
    if (x->h == 0.0) {
        if (wb_fix_step(r, x, h, msg, msg_size) != 0) {
            return 1;
        }
    } else if (fabs(h - x->h) > 1e-9 * x->h) {
        snprintf(msg, msg_size, "fmi2DoStep: communication step %g min differs from the first one (%g min); "
                 "the delay lines hold one input sample per step, so the step is fixed", h, x->h);
        return 1;
    }
    const long long s = x->steps + 1; /* this step */
    double y[4];
    for (int i = 0; i < 2; i++) {
        for (int j = 0; j < 2; j++) {
            const int l = WB_LAG(i, j);
            const long d = x->delay[i][j];
            const double u = d == 0 ? r[VR_REFLUX + j] : wb_past(x, j, s - d);
            const double a = exp(-h / r[VR_TAU11 + l]);
            y[l] = a * r[VR_Y11 + l] + (1.0 - a) * r[VR_K11 + l] * u;
            if (!isfinite(y[l])) {
                snprintf(msg, msg_size, "fmi2DoStep: lag %s became non-finite (inputs reflux = %g, steam = %g)",
                         wb_lag_name[l], r[VR_REFLUX], r[VR_STEAM]);
                return 1;
            }
        }
    }
    for (int l = 0; l < 4; l++) {
        r[VR_Y11 + l] = y[l];
    }
    for (int j = 0; j < 2; j++) {
        x->past[j][s % WB_DELAY_CAPACITY] = r[VR_REFLUX + j];
    }
    x->steps = s;
    for (int i = 0; i < 2; i++) {
        for (int j = 0; j < 2; j++) {
            const long d = x->delay[i][j];
            r[VR_SEEN11 + WB_LAG(i, j)] = d == 0 ? r[VR_REFLUX + j] : wb_past(x, j, s + 1 - d);
        }
    }
    return 0;
}

#include "fmi2_glue.c"
