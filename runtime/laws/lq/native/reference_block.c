/* The lq law's float64 reference step over a campaign block of instances (gainlink.laws.lq.native_block builds and
 * loads this file; gainlink.proof.reference_step writes the same step as Python, the reference this file follows
 * operation for operation: docs/design.md, "The control law").
 *
 * gl_ref_block(dims, mats, count, state, y, y_row, r, r_row, u, sat, flags): instance i's state (row i of `state`,
 * count x (n + q): its estimate xh then its integrator z) is stepped on its sample y + i*y_row (p numbers) and
 * reference r + i*r_row (q numbers; a row of 0 shares one), its command written to row i of u (count x m), its
 * saturation mask (bit j: input j clamped) to sat[i] and its status to flags[i] (1: the sample or reference was not
 * finite, the safe command given and the state kept, as ReferenceLoop refuses it).
 *
 * dims: n, m, p, q, the observer form (1: current, 0: predictor), the anti-windup mode (0 none, 1 clamp, 2 backcalc).
 * mats: y_op, u_op, u_min, u_max, K, Ki, M, Cd, Ci, Kaw, Ad, Bd, Dd, L (row-major), the safe command and Ts.
 *
 * Every product of a row with a vector is summed left to right over all its terms, zeros included, the first term
 * not added to a zero (-0.0 stays -0.0), an empty row giving 0.0; every other operation is the Python step's, in its
 * order. Built with -ffp-contract=off and without -ffast-math: each operation is one IEEE double rounding, as Python's
 * float arithmetic and numpy's elementwise float64 are, so an instance's numbers are its own Python reference's bit
 * for bit, whatever the block's size.
 */
#include <math.h>
#include <stdint.h>

#define GL_REF_MAX 64 /* the widest n, m, p or q this file steps (gl_ref_max; the Python steps wider laws) */

enum { Y_OP, U_OP, U_MIN, U_MAX, K, KI, M, CD, CI, KAW, AD, BD, DD, L, SAFE, TS, MATS };

int64_t gl_ref_max(void) { return GL_REF_MAX; }

/* row . x, left to right over every term (0.0 for an empty row) */
static inline double dot(const double *row, const double *x, int64_t len) {
    if (len == 0) return 0.0;
    double acc = row[0] * x[0];
    for (int64_t j = 1; j < len; j++) acc = acc + row[j] * x[j];
    return acc;
}

static void refuse(const double *const *mats, int64_t m, double *u, int64_t *sat, int64_t *flags) {
    for (int64_t i = 0; i < m; i++) u[i] = mats[SAFE][i];
    *sat = 0;
    *flags = 1;
}

static int finite_all(const double *x, int64_t len) {
    for (int64_t j = 0; j < len; j++)
        if (!isfinite(x[j])) return 0;
    return 1;
}

/* one instance: xh, z (its state) in place; u, *sat written */
static void step_one(const int64_t *dims, const double *const *mats, double *xh, double *z, const double *y,
                     const double *r, double *u, int64_t *sat) {
    const int64_t n = dims[0], m = dims[1], p = dims[2], q = dims[3], current = dims[4], aw = dims[5];
    double dy[GL_REF_MAX], nu[GL_REF_MAX], xcb[GL_REF_MAX], v[GL_REF_MAX], e[GL_REF_MAX], zn[GL_REF_MAX];
    double diff[GL_REF_MAX], du[GL_REF_MAX], w[GL_REF_MAX], xn[GL_REF_MAX];
    int s[GL_REF_MAX];
    const double *xc = xh;
    for (int64_t k = 0; k < p; k++) dy[k] = y[k] - mats[Y_OP][k];
    if (current) {
        for (int64_t k = 0; k < p; k++) nu[k] = dy[k] - dot(mats[CD] + k * n, xh, n);
        for (int64_t i = 0; i < n; i++) xcb[i] = xh[i] + dot(mats[M] + i * p, nu, p);
        xc = xcb;
    }
    int held = 0;
    int64_t mask = 0;
    for (int64_t i = 0; i < m; i++) {
        v[i] = mats[U_OP][i] - dot(mats[K] + i * n, xc, n) - dot(mats[KI] + i * q, z, q);
        double ui = v[i] < mats[U_MIN][i] ? mats[U_MIN][i] : v[i]; /* NaN stays NaN */
        u[i] = ui > mats[U_MAX][i] ? mats[U_MAX][i] : ui;
        s[i] = u[i] != v[i];
        held |= s[i];
        if (s[i]) mask |= (int64_t)1 << i;
    }
    *sat = mask;
    const double Ts = mats[TS][0];
    for (int64_t j = 0; j < q; j++) e[j] = r[j] - dot(mats[CI] + j * p, y, p);
    for (int64_t i = 0; i < m; i++) diff[i] = u[i] - v[i];
    for (int64_t j = 0; j < q; j++) {
        const double grown = z[j] + Ts * e[j];
        if (aw == 1)
            zn[j] = held ? z[j] : grown;
        else if (aw == 2)
            zn[j] = grown + dot(mats[KAW] + j * m, diff, m);
        else
            zn[j] = grown;
    }
    for (int64_t i = 0; i < m; i++) du[i] = u[i] - mats[U_OP][i];
    if (!current)
        for (int64_t k = 0; k < p; k++)
            w[k] = dy[k] - dot(mats[CD] + k * n, xh, n) - dot(mats[DD] + k * m, du, m);
    for (int64_t i = 0; i < n; i++) {
        const double base = dot(mats[AD] + i * n, xc, n) + dot(mats[BD] + i * m, du, m);
        xn[i] = current ? base : base + dot(mats[L] + i * p, w, p);
    }
    for (int64_t i = 0; i < n; i++) xh[i] = xn[i];
    for (int64_t j = 0; j < q; j++) z[j] = zn[j];
}

void gl_ref_block(const int64_t *dims, const double *const *mats, int64_t count, double *state, const double *y,
                  int64_t y_row, const double *r, int64_t r_row, double *u, int64_t *sat, int64_t *flags) {
    const int64_t n = dims[0], m = dims[1], p = dims[2], q = dims[3];
    for (int64_t i = 0; i < count; i++) {
        const double *yi = y + i * y_row, *ri = r + i * r_row;
        double *xh = state + i * (n + q);
        if (!finite_all(yi, p) || !finite_all(ri, q)) {
            refuse(mats, m, u + i * m, sat + i, flags + i);
            continue;
        }
        flags[i] = 0;
        step_one(dims, mats, xh, xh + n, yi, ri, u + i * m, sat + i);
    }
}
