/* The built-in continuous plants' fixed-step RK4 over a batch of runs (gainlink.hil.plants.kernel builds and loads
 * this file; gainlink.hil.plants.models holds each model's numpy definition, the readable one, which this file
 * follows operation for operation).
 *
 * One function per model, gl_ode_<name>(rows, substeps, hh, X, U, P, failed): row r of X (rows x NX, row-major) is
 * advanced by `substeps` classical RK4 steps of length hh under the held inputs U[r] (rows x NU) and the parameters
 * P[r] (rows x NP: the model's parameters, then the products taken once, in the order of OdePlant.native), then
 * clamped. A row whose result is not finite is left as it was and failed[r] set to 1 (0 otherwise); the return is
 * the number of such rows.
 *
 * Each product and sum of a row is taken in the numpy kernel's (models.rk4) order, with no fused multiply-add (built
 * with -ffp-contract=off, without -ffast-math). sin and cos come from SLEEF's deterministic family (Sleef_cinz_*,
 * 1-ulp "u10" variants: no FMA inside, the same bits in every vector extension and in SLEEF's scalar purec build),
 * one call per vector of lanes, so within 1 ulp a call of numpy's and libm's, not bit for bit; tan and sqrt are
 * libm's, per row (sqrt is exactly rounded; tan is scalar per lane, independent of the other lanes).
 *
 * Rows go through in groups of LANES (a partial last group, a batch of one, fills its other lanes with copies of its
 * last row and writes them nowhere): the arithmetic of a group runs in SIMD lanes and its sin/cos is one SLEEF call
 * per vector (the widest cinz extension the compiler is told the build machine has: AVX-512F, else AVX, else SSE2,
 * else the scalar purec per lane; kernel.py picks it). Every operation is elementwise and rounds the same in any
 * lane, and a cinz lane's result depends on its argument alone, so a row's bits do not depend on the batch size or
 * its place in a group.
 */
#include <math.h>
#include <stdint.h>
#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif
#include <sleef.h>

#define LANES 8
#define MAX_STATES 8
#define MAX_INPUTS 4
#define MAX_PARAMS 8

typedef double lanes_t[LANES];
typedef void (*rates_fn)(const lanes_t *x, const lanes_t *u, const lanes_t *p, lanes_t *dx, int g);
typedef void (*clamp_fn)(lanes_t *x);

/* numpy's maximum(v, 0.0): NaN propagates, -0.0 gives +0.0 */
static inline double max0(double v) { return isnan(v) ? v : (v > 0.0 ? v : 0.0); }

/* Columns of `count` rows (width w, from row r0) into lanes, the last row repeated into the lanes past them. */
static inline void gather(lanes_t *dst, const double *src, int w, int64_t r0, int g) {
    for (int j = 0; j < LANES; j++) {
        const double *row = src + (r0 + (j < g ? j : g - 1)) * w;
        for (int i = 0; i < w; i++) dst[i][j] = row[i];
    }
}

static inline __attribute__((always_inline)) int64_t rk4_rows(rates_fn f, clamp_fn clamp, int nx, int nu, int np,
                                                              int64_t rows, int64_t substeps, double hh, double *X,
                                                              const double *U, const double *P,
                                                              unsigned char *failed) {
    const double half = 0.5 * hh, sixth = hh / 6.0;
    int64_t count = 0;
    for (int64_t r = 0; r < rows; r += LANES) {
        const int g = rows - r < LANES ? (int)(rows - r) : LANES;
        lanes_t x[MAX_STATES], t[MAX_STATES], acc[MAX_STATES], u[MAX_INPUTS], p[MAX_PARAMS];
        lanes_t k1[MAX_STATES], k2[MAX_STATES], k3[MAX_STATES], k4[MAX_STATES];
        gather(x, X, nx, r, g);
        gather(u, U, nu, r, g);
        gather(p, P, np, r, g);
        for (int64_t s = 0; s < substeps; s++) { /* x + (hh / 6) (k1 + 2 k2 + 2 k3 + k4), in numpy's order */
            f(x, u, p, k1, g);
            for (int i = 0; i < nx; i++)
                for (int j = 0; j < LANES; j++) t[i][j] = x[i][j] + k1[i][j] * half;
            f(t, u, p, k2, g);
            for (int i = 0; i < nx; i++)
                for (int j = 0; j < LANES; j++) acc[i][j] = k1[i][j] + k2[i][j] * 2.0;
            for (int i = 0; i < nx; i++)
                for (int j = 0; j < LANES; j++) t[i][j] = x[i][j] + k2[i][j] * half;
            f(t, u, p, k3, g);
            for (int i = 0; i < nx; i++)
                for (int j = 0; j < LANES; j++) t[i][j] = x[i][j] + k3[i][j] * hh;
            f(t, u, p, k4, g);
            for (int i = 0; i < nx; i++)
                for (int j = 0; j < LANES; j++) acc[i][j] = (acc[i][j] + k3[i][j] * 2.0) + k4[i][j];
            for (int i = 0; i < nx; i++)
                for (int j = 0; j < LANES; j++) x[i][j] = x[i][j] + acc[i][j] * sixth;
        }
        if (clamp) clamp(x);
        for (int j = 0; j < g; j++) {
            int finite = 1;
            for (int i = 0; i < nx; i++) finite &= isfinite(x[i][j]) != 0;
            failed[r + j] = (unsigned char)!finite;
            count += !finite;
            if (finite)
                for (int i = 0; i < nx; i++) X[(r + j) * nx + i] = x[i][j];
        }
    }
    return count;
}

/* sin and cos of the LANES values in x, through SLEEF's deterministic 1-ulp sincos. */
static inline void sincos_lanes(const double *x, double *s, double *c) {
#if defined(__AVX512F__)
    Sleef___m512d_2 r = Sleef_cinz_sincosd8_u10avx512fnofma(_mm512_loadu_pd(x));
    _mm512_storeu_pd(s, r.x), _mm512_storeu_pd(c, r.y);
#elif defined(__AVX__)
    for (int j = 0; j < LANES; j += 4) {
        Sleef___m256d_2 r = Sleef_cinz_sincosd4_u10avx(_mm256_loadu_pd(x + j));
        _mm256_storeu_pd(s + j, r.x), _mm256_storeu_pd(c + j, r.y);
    }
#elif defined(__SSE2__)
    for (int j = 0; j < LANES; j += 2) {
        Sleef___m128d_2 r = Sleef_cinz_sincosd2_u10sse2(_mm_loadu_pd(x + j));
        _mm_storeu_pd(s + j, r.x), _mm_storeu_pd(c + j, r.y);
    }
#else
    for (int j = 0; j < LANES; j++) {
        Sleef_double_2 r = Sleef_cinz_sincosd1_u10purec(x[j]);
        s[j] = r.x, c[j] = r.y;
    }
#endif
}

/* CartPendulum. x = (x, x_dot, theta, theta_dot), u = (F), p = (M, m, l, g, ml, mg, Mmg). */
static inline void cart_pendulum(const lanes_t *x, const lanes_t *u, const lanes_t *p, lanes_t *dx, int g) {
    (void)g; /* the lanes past g hold copies of the last row: stepped alike, written nowhere */
    lanes_t s, c;
    sincos_lanes(x[2], s, c);
    for (int j = 0; j < LANES; j++) {
        const double M = p[0][j], m = p[1][j], l = p[2][j], ml = p[4][j], mg = p[5][j], Mmg = p[6][j];
        const double w = x[3][j], D = M + m * s[j] * s[j], f = u[0][j] + ml * w * w * s[j];
        dx[0][j] = x[1][j];
        dx[1][j] = (f - mg * s[j] * c[j]) / D;
        dx[2][j] = w;
        dx[3][j] = (Mmg * s[j] - c[j] * f) / (l * D);
    }
}

/* QuadrotorLateral. x = (phi, p, v, y), u = (tau), p = (g, Ixx, mass, c_d). */
static inline void quadrotor_lateral(const lanes_t *x, const lanes_t *u, const lanes_t *p, lanes_t *dx, int g) {
    lanes_t t;
    for (int j = 0; j < g; j++) t[j] = tan(x[0][j]);
    for (int j = g; j < LANES; j++) t[j] = t[g - 1];
    for (int j = 0; j < LANES; j++) {
        const double grav = p[0][j], Ixx = p[1][j], mass = p[2][j], c_d = p[3][j], v = x[2][j];
        dx[0][j] = x[1][j];
        dx[1][j] = u[0][j] / Ixx;
        dx[2][j] = grav * t[j] - c_d / mass * v;
        dx[3][j] = v;
    }
}

/* Tank. x = (q, h), u = (u), p = (c, tau_p, area, flare). */
static inline void tank(const lanes_t *x, const lanes_t *u, const lanes_t *p, lanes_t *dx, int g) {
    (void)g;
    for (int j = 0; j < LANES; j++) {
        const double c = p[0][j], tau_p = p[1][j], area = p[2][j], flare = p[3][j];
        const double h = max0(x[1][j]), section = area + flare * h;
        dx[0][j] = (u[0][j] - x[0][j]) / tau_p;
        dx[1][j] = (x[0][j] - c * sqrt(h)) / section;
    }
}

static inline void tank_clamp(lanes_t *x) {
    for (int j = 0; j < LANES; j++) x[1][j] = max0(x[1][j]);
}

#define GL_ODE(name, nx, nu, np, clamp)                                                                             \
    int64_t gl_ode_##name(int64_t rows, int64_t substeps, double hh, double *X, const double *U, const double *P, \
                          unsigned char *failed) {                                                              \
        return rk4_rows(name, clamp, nx, nu, np, rows, substeps, hh, X, U, P, failed);                          \
    }

GL_ODE(cart_pendulum, 4, 1, 7, 0)
GL_ODE(quadrotor_lateral, 4, 1, 4, 0)
GL_ODE(tank, 2, 1, 4, tank_clamp)
