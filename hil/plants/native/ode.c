/* The built-in continuous plants' fixed-step RK4 over a batch of runs (gainlink.hil.plants.kernel builds and loads
 * this file; gainlink.hil.plants.models holds each model's numpy definition, the readable one, which this file
 * follows operation for operation).
 *
 * One function per model, gl_ode_<name>(rows, substeps, hh, X, U, P, failed): row r of X (rows x NX, row-major) is
 * advanced by `substeps` classical RK4 steps of length hh under the held inputs U[r] (rows x NU) and the parameters
 * P[r] (rows x NP: the model's parameters, then the products taken once, in the order kernel.py lists), then
 * clamped. A row whose result is not finite is left as it was and failed[r] set to 1 (0 otherwise); the return is
 * the number of such rows.
 *
 * Bit for bit what the numpy kernel (models.rk4) computes: each product and sum of a row in the same order, no
 * fused multiply-add (built with -ffp-contract=off, without -ffast-math), sin, cos, tan and sqrt from libm called
 * per row (no vectorised math library: its SIMD body would round other bits than its scalar tail), every row on its
 * own, so a row's bits are the same at any batch size.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#define MAX_STATES 8

typedef void (*rates_fn)(const double *x, const double *u, const double *p, double *dx);
typedef void (*clamp_fn)(double *x);

/* numpy's maximum(v, 0.0): NaN propagates, -0.0 gives +0.0 */
static inline double max0(double v) { return isnan(v) ? v : (v > 0.0 ? v : 0.0); }

static inline __attribute__((always_inline)) int64_t rk4_rows(rates_fn f, clamp_fn clamp, int nx, int nu, int np,
                                                              int64_t rows, int64_t substeps, double hh, double *X,
                                                              const double *U, const double *P,
                                                              unsigned char *failed) {
    const double half = 0.5 * hh, sixth = hh / 6.0;
    int64_t count = 0;
    for (int64_t r = 0; r < rows; r++) {
        const double *u = U + r * nu, *p = P + r * np;
        double *row = X + r * nx;
        double x[MAX_STATES], t[MAX_STATES], acc[MAX_STATES];
        double k1[MAX_STATES], k2[MAX_STATES], k3[MAX_STATES], k4[MAX_STATES];
        memcpy(x, row, (size_t)nx * sizeof(double));
        for (int64_t s = 0; s < substeps; s++) { /* x + (hh / 6) (k1 + 2 k2 + 2 k3 + k4), in numpy's order */
            f(x, u, p, k1);
            for (int i = 0; i < nx; i++) t[i] = x[i] + k1[i] * half;
            f(t, u, p, k2);
            for (int i = 0; i < nx; i++) acc[i] = k1[i] + k2[i] * 2.0;
            for (int i = 0; i < nx; i++) t[i] = x[i] + k2[i] * half;
            f(t, u, p, k3);
            for (int i = 0; i < nx; i++) t[i] = x[i] + k3[i] * hh;
            f(t, u, p, k4);
            for (int i = 0; i < nx; i++) acc[i] = (acc[i] + k3[i] * 2.0) + k4[i];
            for (int i = 0; i < nx; i++) x[i] = x[i] + acc[i] * sixth;
        }
        if (clamp) clamp(x);
        int finite = 1;
        for (int i = 0; i < nx; i++) finite &= isfinite(x[i]) != 0;
        failed[r] = (unsigned char)!finite;
        count += !finite;
        if (finite) memcpy(row, x, (size_t)nx * sizeof(double));
    }
    return count;
}

/* CartPendulum. x = (x, x_dot, theta, theta_dot), u = (F), p = (M, m, l, g, ml, mg, Mmg). */
static inline void cart_pendulum(const double *x, const double *u, const double *p, double *dx) {
    const double M = p[0], m = p[1], l = p[2], ml = p[4], mg = p[5], Mmg = p[6];
    const double w = x[3], s = sin(x[2]), c = cos(x[2]);
    const double D = M + m * s * s;
    const double f = u[0] + ml * w * w * s;
    dx[0] = x[1];
    dx[1] = (f - mg * s * c) / D;
    dx[2] = w;
    dx[3] = (Mmg * s - c * f) / (l * D);
}

/* QuadrotorLateral. x = (phi, p, v, y), u = (tau), p = (g, Ixx, mass, c_d). */
static inline void quadrotor_lateral(const double *x, const double *u, const double *p, double *dx) {
    const double g = p[0], Ixx = p[1], mass = p[2], c_d = p[3], v = x[2];
    dx[0] = x[1];
    dx[1] = u[0] / Ixx;
    dx[2] = g * tan(x[0]) - c_d / mass * v;
    dx[3] = v;
}

/* Tank. x = (q, h), u = (u), p = (c, tau_p, area, flare). */
static inline void tank(const double *x, const double *u, const double *p, double *dx) {
    const double c = p[0], tau_p = p[1], area = p[2], flare = p[3];
    const double h = max0(x[1]), section = area + flare * h;
    dx[0] = (u[0] - x[0]) / tau_p;
    dx[1] = (x[0] - c * sqrt(h)) / section;
}

static inline void tank_clamp(double *x) { x[1] = max0(x[1]); }

#define GL_ODE(name, nx, nu, np, clamp)                                                                             \
    int64_t gl_ode_##name(int64_t rows, int64_t substeps, double hh, double *X, const double *U, const double *P, \
                          unsigned char *failed) {                                                              \
        return rk4_rows(name, clamp, nx, nu, np, rows, substeps, hh, X, U, P, failed);                          \
    }

GL_ODE(cart_pendulum, 4, 1, 7, 0)
GL_ODE(quadrotor_lateral, 4, 1, 4, 0)
GL_ODE(tank, 2, 1, 4, tank_clamp)
