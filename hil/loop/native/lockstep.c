/* A campaign block's closed loop over all its steps in one call (gainlink.hil.loop.lockstep builds and loads this
 * file; gainlink.hil.loop.block._python_lockstep is the same loop in numpy, the oracle this file follows operation
 * for operation: docs/design.md, "Campaign blocks").
 *
 * gl_lockstep(plan, plant, law, rec): for k = 0 .. steps-1, for the whole block at once:
 *   1. each run's sample y = the plant's selected outputs + the run's noise at k (its own plan's array, drawn in
 *      Python before the loop), recorded (and the plants' states, when asked);
 *   2. the law's block step, one call through the function pointer handed over (the clock read around it, ns):
 *      kind 0, any law of a host law library (gl_host_law_step_block: samples cast to float32 into its sample
 *      records, its records read back: the command, flags, saturation, sigma); kind 1, the lq law's float64
 *      reference (gl_ref_block of gainlink/laws/lq/native/reference_block.c, its states recorded when asked);
 *   3. each run's command (plus its disturbance at k where the run is disturbed) held on its plant's selected inputs,
 *      and the plants advanced by the compiled RK4 (gl_ode_<model> of gainlink/hil/plants/native/ode.c, through its
 *      pointer: the same function a plant alone steps with);
 *   4. a run whose plant fails (non-finite) ends after that step (its row steps on, its records written and never
 *      read); when every run has ended, the loop stops.
 * Records are written run-major, straight into their arrays: row (i, k) of a record of width w at (i*steps + k)*w.
 *
 * The runs are stepped SPAN at a time, each span through all its steps before the next: each run's records and plan
 * rows are then read and written in order while its lines are in cache (a whole block per step touched a line of
 * every run's every record each step, ~1 MB a step at 1,000 runs, beyond L2). A run's numbers do not depend on the
 * others' (the law's instances, the RK4's rows: ode.c) so they are those of the block stepped a step at a time. A
 * span whose runs have all ended stops; once every span has run, those that stopped before the longest run's end
 * step on to it (as the runs of a block stepped a step at a time do). A step's law time (lat) is the sum of its
 * spans' calls; its tick, the sum of the earlier steps' times over all spans: the block's own clock, as if it had
 * stepped a step at a time.
 *
 * Every floating-point operation is one IEEE double rounding (built with -ffp-contract=off, without -ffast-math), in
 * the numpy loop's order: an addition each for the sample and the disturbed command, casts float64 <-> float32 as
 * numpy's astype, so each record is the numpy loop's bit for bit.
 */
#define _POSIX_C_SOURCE 199309L /* clock_gettime under -std=c11 */
#include <stdint.h>
#include <string.h>
#include <time.h>

typedef void (*host_block_fn)(void *laws, uint32_t count, const void *in, void *out);
typedef void (*ref_block_fn)(const int64_t *dims, const void *mats, int64_t count, double *state, const double *y,
                             int64_t y_row, const double *r, int64_t r_row, double *u, int64_t *sat, int64_t *flags);
typedef int64_t (*ode_fn)(int64_t rows, int64_t substeps, double hh, double *X, const double *U, const double *P,
                          unsigned char *failed);

/* What each run is fed: per run, the address of its plan's (steps x width) row-major arrays. */
typedef struct {
    int64_t runs, steps;
    const double *const *noise; /* width p */
    const double *const *r;     /* width q (0: the law's references are zero) */
    const double *const *s;     /* width e */
    const double *const *d;     /* width m */
    int64_t p, q, e, m;
    const unsigned char *disturbed; /* per run: the command goes to the plant plus its disturbance */
} gl_ls_plan_t;

/* The plants: the compiled RK4's rows (gainlink.hil.plants.kernel.Rows), advanced in place. */
typedef struct {
    void *fn;
    double *X;       /* runs x nx */
    double *U;       /* runs x nu: the full inputs, the ones not selected left as they are (zero) */
    const double *P; /* runs x the model's parameter columns */
    unsigned char *failed;
    int64_t nx, nu, npar, substeps;
    double hh;
    const int64_t *out_idx; /* p: the states sampled */
    const int64_t *in_idx;  /* m: the inputs commanded */
} gl_ls_plant_t;

/* How a block law is called (the law's c_law() says which; not which law it is: every law a host library builds
 * comes as HOST_RECORDS): kind 0, a host law library's block step on float32 sample and record layouts (byte
 * offsets into them); kind 1, a float64 block step on columns (its scratch buffers). */
enum { HOST_RECORDS = 0, FLOAT64_COLUMNS = 1 };

typedef struct {
    int64_t kind;
    void *fn;
    void *laws;
    int64_t law_bytes; /* one instance */
    unsigned char *samples;
    const unsigned char *records;
    int64_t sample_bytes, y_off, r_off, s_off, law_q, law_e;
    int64_t record_bytes, flags_off, sat_off, u_off, sigma_off; /* sigma_off < 0: the law has none */
    int64_t fault;                                              /* the fault flag's bit */
    const int64_t *dims;
    const void *mats;
    double *state; /* runs x state_width */
    int64_t state_width;
    int64_t kept_from, kept; /* the columns [kept_from, kept_from + kept) of a state recorded (rec->L) */
    int64_t *sat;    /* runs */
    int64_t *flags;  /* runs: 1 refused */
    double *r;       /* runs x q, the step's references gathered */
} gl_ls_law_t;

/* The records, run-major (runs x steps x width); NULL: not recorded. */
typedef struct {
    double *Y, *U;
    int64_t *sat, *flags;
    double *sigma, *X, *L;
    int64_t *done, *failed_at; /* per run */
    double *tick, *lat;        /* per step, ns (zero: tick sums each step's time first) */
    unsigned char *alive;      /* per run, scratch */
} gl_ls_record_t;

int64_t gl_lockstep_sizes(int64_t which)
{
    switch (which) {
    case 0: return (int64_t)sizeof(gl_ls_plan_t);
    case 1: return (int64_t)sizeof(gl_ls_plant_t);
    case 2: return (int64_t)sizeof(gl_ls_law_t);
    case 3: return (int64_t)sizeof(gl_ls_record_t);
    default: return -1;
    }
}

static inline int64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts); /* Python's perf_counter_ns */
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static inline void put_f32(unsigned char *at, double v)
{
    const float f = (float)v;
    memcpy(at, &f, sizeof f);
}

static inline float get_f32(const unsigned char *at)
{
    float f;
    memcpy(&f, at, sizeof f);
    return f;
}

static inline uint32_t get_u32(const unsigned char *at)
{
    uint32_t w;
    memcpy(&w, at, sizeof w);
    return w;
}

/* The runs [i0, i0 + n) of a span. */
typedef struct {
    int64_t i0, n;
} span_t;

/* 1: each run's sample, recorded; the plants' states recorded when asked. */
static void sample(const gl_ls_plan_t *pl, const gl_ls_plant_t *pt, const gl_ls_record_t *rec, span_t sp, int64_t k)
{
    const int64_t N = pl->steps, p = pl->p, nx = pt->nx;
    for (int64_t i = sp.i0; i < sp.i0 + sp.n; i++) {
        const double *x = pt->X + i * nx, *noise = pl->noise[i] + k * p;
        double *y = rec->Y + (i * N + k) * p;
        for (int64_t j = 0; j < p; j++) y[j] = x[pt->out_idx[j]] + noise[j];
        if (rec->X)
            for (int64_t j = 0; j < nx; j++) rec->X[(i * N + k) * nx + j] = x[j];
    }
}

/* 2, kind 0: a host law library's block step over the span; the command of run i into u[i*m ..]. Returns the
 * call's time, ns. */
static int64_t host_law(const gl_ls_plan_t *pl, const gl_ls_law_t *lw, const gl_ls_record_t *rec, span_t sp,
                        int64_t k, double *u)
{
    const int64_t N = pl->steps, p = pl->p, m = pl->m;
    for (int64_t i = sp.i0; i < sp.i0 + sp.n; i++) {
        unsigned char *at = lw->samples + i * lw->sample_bytes;
        const double *y = rec->Y + (i * N + k) * p;
        for (int64_t j = 0; j < p; j++) put_f32(at + lw->y_off + 4 * j, y[j]);
        for (int64_t j = 0; j < lw->law_q; j++)
            put_f32(at + lw->r_off + 4 * j, j < pl->q ? pl->r[i][k * pl->q + j] : 0.0);
        for (int64_t j = 0; j < lw->law_e; j++)
            put_f32(at + lw->s_off + 4 * j, j < pl->e ? pl->s[i][k * pl->e + j] : 0.0);
    }
    const int64_t t0 = now_ns();
    ((host_block_fn)lw->fn)((unsigned char *)lw->laws + sp.i0 * lw->law_bytes, (uint32_t)sp.n,
                            lw->samples + sp.i0 * lw->sample_bytes,
                            (void *)(lw->records + sp.i0 * lw->record_bytes));
    const int64_t took = now_ns() - t0;
    for (int64_t i = sp.i0; i < sp.i0 + sp.n; i++) {
        const unsigned char *at = lw->records + i * lw->record_bytes;
        const uint32_t flags = get_u32(at + lw->flags_off), sat = get_u32(at + lw->sat_off);
        for (int64_t j = 0; j < m; j++) u[i * m + j] = (double)get_f32(at + lw->u_off + 4 * j);
        if (rec->flags) rec->flags[i * N + k] = (int64_t)flags;
        if (rec->sat) rec->sat[i * N + k] = (flags & (uint32_t)lw->fault) ? 0 : (int64_t)sat; /* a fault clamps none */
        if (rec->sigma && lw->sigma_off >= 0) rec->sigma[i * N + k] = (double)get_f32(at + lw->sigma_off);
    }
    return took;
}

/* 2, kind 1: the float64 reference's block step over the span (the columns of its states kept, when asked: the
 * integrators, all of them that is read). Returns the call's time, ns. */
static int64_t reference_law(const gl_ls_plan_t *pl, const gl_ls_law_t *lw, const gl_ls_record_t *rec, span_t sp,
                             int64_t k, double *u)
{
    const int64_t N = pl->steps, p = pl->p, m = pl->m, q = lw->law_q, w = lw->state_width, kw = lw->kept;
    for (int64_t i = sp.i0; i < sp.i0 + sp.n; i++)
        for (int64_t j = 0; j < q; j++) lw->r[i * q + j] = j < pl->q ? pl->r[i][k * pl->q + j] : 0.0;
    const int64_t t0 = now_ns();
    ((ref_block_fn)lw->fn)(lw->dims, lw->mats, sp.n, lw->state + sp.i0 * w, rec->Y + (sp.i0 * N + k) * p, N * p,
                           lw->r + sp.i0 * q, q, u + sp.i0 * m, lw->sat + sp.i0, lw->flags + sp.i0);
    const int64_t took = now_ns() - t0;
    for (int64_t i = sp.i0; i < sp.i0 + sp.n; i++) {
        if (rec->flags) rec->flags[i * N + k] = lw->flags[i] * lw->fault;
        if (rec->sat) rec->sat[i * N + k] = lw->sat[i];
        if (rec->L)
            for (int64_t j = 0; j < kw; j++) rec->L[(i * N + k) * kw + j] = lw->state[i * w + lw->kept_from + j];
    }
    return took;
}

/* 3: the commands recorded and held on the plants (plus the disturbance where the run is disturbed); the span's
 * plants advanced. Returns the number of its rows whose advance failed. */
static int64_t command(const gl_ls_plan_t *pl, gl_ls_plant_t *pt, const gl_ls_record_t *rec, span_t sp, int64_t k,
                       const double *u)
{
    const int64_t N = pl->steps, m = pl->m;
    for (int64_t i = sp.i0; i < sp.i0 + sp.n; i++) {
        const double *d = pl->d[i] + k * m;
        for (int64_t j = 0; j < m; j++) {
            const double ui = u[i * m + j];
            rec->U[(i * N + k) * m + j] = ui;
            pt->U[i * pt->nu + pt->in_idx[j]] = pl->disturbed[i] ? ui + d[j] : ui;
        }
    }
    return ((ode_fn)pt->fn)(sp.n, pt->substeps, pt->hh, pt->X + sp.i0 * pt->nx, pt->U + sp.i0 * pt->nu,
                            pt->P + sp.i0 * pt->npar, pt->failed + sp.i0);
}

/* 4: the span's runs whose plant failed now end after step k; 1 when none of its runs is left. */
static int end_failed(const gl_ls_plant_t *pt, const gl_ls_record_t *rec, span_t sp, int64_t k)
{
    int newly = 0, left = 0;
    for (int64_t i = sp.i0; i < sp.i0 + sp.n; i++) {
        if (pt->failed[i] && rec->alive[i]) {
            rec->done[i] = k + 1, rec->failed_at[i] = k, rec->alive[i] = 0;
            newly = 1;
        }
        left |= rec->alive[i];
    }
    return newly && !left;
}

/* The span's steps [from, to): returns the step it stopped before (to, or the step after which its last run
 * ended). Each step's time is added to tick[k] (made the block's clock by the caller) and the law's to lat[k]. */
static int64_t run_span(const gl_ls_plan_t *pl, gl_ls_plant_t *pt, const gl_ls_law_t *lw, const gl_ls_record_t *rec,
                        double *u, span_t sp, int64_t from, int64_t to)
{
    int64_t t0 = now_ns();
    for (int64_t k = from; k < to; k++) {
        sample(pl, pt, rec, sp, k);
        const int64_t took = lw->kind == HOST_RECORDS ? host_law(pl, lw, rec, sp, k, u)
                                                      : reference_law(pl, lw, rec, sp, k, u);
        rec->lat[k] += (double)took;
        const int ended = command(pl, pt, rec, sp, k, u) && end_failed(pt, rec, sp, k);
        const int64_t t1 = now_ns();
        rec->tick[k] += (double)(t1 - t0);
        t0 = t1;
        if (ended) return k + 1;
    }
    return to;
}

#ifndef SPAN
#define SPAN 32 /* runs a span steps (a multiple of ode.c's 8 lanes) */
#endif

static inline span_t span_at(const gl_ls_plan_t *pl, int64_t i0)
{
    const span_t sp = {i0, pl->runs - i0 < SPAN ? pl->runs - i0 : SPAN};
    return sp;
}

/* Where the span stopped: the last step if a run of it is left, else the step after its last run ended. */
static int64_t span_end(const gl_ls_plan_t *pl, const gl_ls_record_t *rec, span_t sp)
{
    int64_t end = 0;
    for (int64_t i = sp.i0; i < sp.i0 + sp.n; i++) {
        if (rec->alive[i]) return pl->steps;
        if (rec->done[i] > end) end = rec->done[i];
    }
    return end;
}

/* The block's loop (the file's comment); returns the steps its longest run took (rows past them are not written),
 * -1 for a law kind this file does not know. u: runs x m scratch. */
int64_t gl_lockstep(const gl_ls_plan_t *pl, gl_ls_plant_t *pt, const gl_ls_law_t *lw, const gl_ls_record_t *rec,
                    double *u)
{
    if (lw->kind != HOST_RECORDS && lw->kind != FLOAT64_COLUMNS) return -1;
    for (int64_t i = 0; i < pl->runs; i++) rec->done[i] = pl->steps, rec->failed_at[i] = -1, rec->alive[i] = 1;
    for (int64_t k = 0; k < pl->steps; k++) rec->tick[k] = 0.0, rec->lat[k] = 0.0;
    int64_t taken = 0;
    for (int64_t i0 = 0; i0 < pl->runs; i0 += SPAN) {
        const int64_t end = run_span(pl, pt, lw, rec, u, span_at(pl, i0), 0, pl->steps);
        if (end > taken) taken = end;
    }
    for (int64_t i0 = 0; i0 < pl->runs; i0 += SPAN) { /* step on to the longest run's end */
        const int64_t end = span_end(pl, rec, span_at(pl, i0));
        if (end < taken) run_span(pl, pt, lw, rec, u, span_at(pl, i0), end, taken);
    }
    double before = 0.0; /* each step's tick: the time of the steps before it */
    for (int64_t k = 0; k < taken; k++) {
        const double step = rec->tick[k];
        rec->tick[k] = before;
        before += step;
    }
    return taken;
}
