/* SPDX-License-Identifier: MIT */
/*
 * bench_step: what one step costs, per integrator, in and out of contact, and how fast the default
 * scene runs against real time. It reports; it never fails on speed.
 *
 * Two ways of measuring, because each hides something the other shows:
 *   kernel - the integrator's run() loop driven directly on a prepared vafm_kernel (core/kernel.h),
 *            the body held in a stationary state (support at rest), so nothing but steps is timed;
 *   scene  - whole force curves / tunes through vafm_sim, time divided by result.steps, so the cost
 *            includes sampling, phase logic, contact events and the solver's real warm starts.
 * Each number is the median of S_REPS repetitions of at least S_MIN_REP_S seconds of work (wall clock,
 * CLOCK_MONOTONIC; the CPU clock of the process is reported alongside). Ratios are against the paper's
 * method (paper-vv with uniform noise) measured in the same run, same method and same place.
 *
 * Usage: bench_step [outdir]   writes outdir/bench_step.csv, bench_step_rtf.csv, bench_step.md and
 * prints the markdown to stdout.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"
#include "vafm/integrator.h"
#include "vafm/params.h"
#include "vafm/sim.h"
#include "vafm/theory.h"
#include "vafm/units.h"
#include "core/internal.h"
#include "core/kernel.h"

#define S_REPS 5
#define S_MIN_REP_S 0.2
#define S_KERNEL_CHUNK 100000L
#define S_RTF_LIMIT_S 60.0  /* a real-time-factor curve is cut after this much wall time, its rate kept */
#define S_MAX_ROWS 32
#define S_MAX_RTF 8

/* ---- clocks ------------------------------------------------------------------------------------ */

typedef struct s_clock {
    double wall, cpu; /* s */
} s_clock;

static s_clock s_now(void)
{
    s_clock c = { bench_clock_s(CLOCK_MONOTONIC), bench_clock_s(CLOCK_PROCESS_CPUTIME_ID) };
    return c;
}

/* ---- measurement ------------------------------------------------------------------------------- */

/* A workload does some steps and returns how many. */
typedef uint64_t (*s_work_fn)(void *ctx);

typedef struct s_meas {
    double ns_med, ns_min, ns_max; /* wall ns per step over the repetitions */
    double ns_cpu_med;             /* process CPU ns per step, median */
} s_meas;

static s_meas s_measure(s_work_fn work, void *ctx)
{
    double ns[S_REPS], ns_cpu[S_REPS];
    work(ctx); /* warm-up: caches, page faults, branch predictors */
    for (int r = 0; r < S_REPS; r++) {
        uint64_t steps = 0;
        s_clock t0 = s_now(), t1;
        do {
            steps += work(ctx);
            t1 = s_now();
        } while (t1.wall - t0.wall < S_MIN_REP_S);
        ns[r] = 1e9 * (t1.wall - t0.wall) / (double)steps;
        ns_cpu[r] = 1e9 * (t1.cpu - t0.cpu) / (double)steps;
    }
    qsort(ns, S_REPS, sizeof ns[0], bench_cmp_double);
    qsort(ns_cpu, S_REPS, sizeof ns_cpu[0], bench_cmp_double);
    s_meas m = { ns[S_REPS / 2], ns[0], ns[S_REPS - 1], ns_cpu[S_REPS / 2] };
    return m;
}

/* ---- scenes ------------------------------------------------------------------------------------ */

/* The paper's Fig. 4 scene (γ̃ = 0.229, k̃ = 0.1, m̃ = 0.01, k_BT̃ = 0.01, ṽ = 1e-3) pressed in: the
 * support starts 0.1 R past the contact point, so the body starts in contact at thermal equilibrium,
 * the approach ends 0.01 R later on the height trigger and the retract runs through the pull-off.
 * In-contact steps are ~98% of a curve's steps. */
static void s_scene_fig4_pressed(vafm_params *p, const vafm_integrator_type *it)
{
    vafm_preset_apply(p, "paper-fig4", NULL);
    const double R = p->R_m;
    p->start_height_m = -0.1 * R;
    p->trigger = VAFM_TRIGGER_HEIGHT;
    p->trigger_height_m = -0.11 * R;
    p->integrator = it;
    p->noise = it == vafm_integrator_paper_vv ? VAFM_NOISE_UNIFORM : VAFM_NOISE_GAUSSIAN;
}

/* The same scene with the support 20 R away from the surface (20 R = 63 thermal standard deviations of
 * the free cantilever): a thermal tune there never touches. */
static void s_scene_fig4_far(vafm_params *p, const vafm_integrator_type *it, int free_exact)
{
    s_scene_fig4_pressed(p, it);
    p->start_height_m = 20.0 * p->R_m;
    p->free_exact = free_exact;
}

/* ---- kernel workloads -------------------------------------------------------------------------- */

typedef struct s_kwork {
    vafm_kernel K;
    const vafm_integrator_type *it;
    vafm_jkr_table jtab;
    vafm_free_ou ou;
    int free_ou;      /* 1: time the exact free propagation instead of the integrator */
    uint64_t events;  /* contact changes seen (0 for clean numbers) */
} s_kwork;

/* A kernel built as vafm_sim_new() builds it (same fields, same contact table, same free step) for
 * scene p, with the support at rest at u_spr and the body at its noise-free equilibrium: on the JKR
 * branch when in_contact, else at the relaxed spring. Release with s_kwork_fini(). */
static int s_kwork_init(s_kwork *w, const vafm_params *p, double u_spr, int in_contact)
{
    vafm_numerics nm;
    vafm_error err;
    memset(w, 0, sizeof *w);
    if (vafm_numerics_check(p, &nm, &err)) {
        fprintf(stderr, "bench_step: %s\n", err.message);
        return -1;
    }
    vafm_kernel *K = &w->K;
    w->it = p->integrator;
    K->m = nm.r.m;
    K->k = nm.r.k;
    K->kT = nm.r.kT;
    K->eta_c = nm.r.eta_cont;
    K->contact = nm.contact;
    K->cforce = K->contact.type->force;
    K->is_jkr = K->contact.type == vafm_contact_jkr;
    if (p->contact_table && K->is_jkr && K->contact.gamma > 0 &&
        vafm_jkr_table_init(&w->jtab, &K->contact, nm.u_deep) == 0)
        K->jtab = &w->jtab;
    K->thermal = nm.r.kT > 0;
    K->uniform_noise = p->noise == VAFM_NOISE_UNIFORM;
    vafm_rng_init(&K->rng, p->seed, 0);
    vafm_kernel_set_dt(K, nm.dt);
    K->u_spr = K->uspr0 = u_spr;
    K->v_spr = 0.0;
    K->u = u_spr;
    K->fs_min = INFINITY;
    if (in_contact) {
        double F;
        if (vafm_theory_equilibrium(nm.r.gamma, nm.r.k, u_spr, &K->u, &F)) {
            fprintf(stderr, "bench_step: no contact equilibrium at u_spr = %g\n", u_spr);
            vafm_jkr_table_free(&w->jtab);
            return -1;
        }
        K->in_contact = 1;
        K->Fc = K->cforce(&K->contact, K->u, &K->s, NULL);
    }
    w->it->prepare(K);
    /* the free step of the scene: the sample interval split as vafm_sim_new() splits it */
    double h_target = w->it->overdamped ? 0.25 * K->co[0].zeta / K->k : 0.25 / fmax(1.0, sqrt(K->k / K->m));
    long nf = (long)ceil(nm.Ts / h_target);
    nf = nf > nm.n_sub ? nm.n_sub : nf < 1 ? 1 : nf;
    vafm_free_ou_setup(&w->ou, K, nm.Ts / (double)nf, w->it->overdamped);
    return 0;
}

static void s_kwork_fini(s_kwork *w)
{
    vafm_jkr_table_free(&w->jtab);
    w->K.jtab = NULL;
}

static uint64_t s_kwork_run(void *ctx)
{
    s_kwork *w = ctx;
    vafm_kernel *K = &w->K;
    if (w->free_ou) {
        K->dt = w->ou.h;
        vafm_free_ou_steps(K, &w->ou, S_KERNEL_CHUNK); /* as the scene does a sample interval's steps */
        return S_KERNEL_CHUNK;
    }
    long left = S_KERNEL_CHUNK;
    while (left > 0) {
        left -= w->it->run(K, left);
        if (K->event) {
            w->events++;
            K->event = 0;
        }
    }
    return S_KERNEL_CHUNK;
}

/* ---- scene workloads --------------------------------------------------------------------------- */

typedef struct s_swork {
    vafm_sim *sim;
    int tune;         /* 1: thermal tune, 0: force curve */
    uint64_t index;   /* next curve index (each repetition sees new curves) */
    uint64_t steps, steps_contact, steps_free; /* totals, for the step mix */
    double time_s;    /* the reduced time unit, s */
    double sim_time;  /* total simulated time (reduced) */
    int failed;       /* a scene returned an error */
} s_swork;

static uint64_t s_swork_run(void *ctx)
{
    s_swork *w = ctx;
    vafm_curve_result res;
    int r = w->tune ? vafm_sim_tune(w->sim, w->index, NULL, NULL) : vafm_sim_curve(w->sim, w->index, NULL, NULL, NULL);
    w->index++;
    vafm_sim_result(w->sim, &res);
    if (r)
        w->failed = r;
    w->steps += res.steps;
    w->steps_contact += res.steps_contact;
    w->steps_free += res.steps_free;
    w->sim_time += res.duration_s / w->time_s;
    return res.steps > 0 ? res.steps : 1;
}

/* ---- results ----------------------------------------------------------------------------------- */

typedef struct s_row {
    const char *integrator, *where, *method;
    double dt;      /* reduced time per step */
    s_meas m;
    double ratio, ratio_cpu; /* against paper-vv, same where and method: wall and CPU medians */
    char note[96];
} s_row;

typedef struct s_bench {
    s_row rows[S_MAX_ROWS];
    int n;
    double load0, load1; /* 1-minute load average before and after */
} s_bench;

static s_row *s_add(s_bench *b, const char *integrator, const char *where, const char *method, double dt, s_meas m)
{
    if (b->n >= S_MAX_ROWS)
        return NULL;
    s_row *r = &b->rows[b->n++];
    memset(r, 0, sizeof *r);
    r->integrator = integrator;
    r->where = where;
    r->method = method;
    r->dt = dt;
    r->m = m;
    r->ratio = r->ratio_cpu = NAN;
    fprintf(stderr, "  %-8s %-18s %-22s %8.2f ns/step (%.2f..%.2f)\n", method, where, integrator, m.ns_med, m.ns_min,
            m.ns_max);
    return r;
}

static void s_ratios(s_bench *b)
{
    for (int i = 0; i < b->n; i++) {
        s_row *r = &b->rows[i];
        for (int j = 0; j < b->n; j++) {
            const s_row *q = &b->rows[j];
            if (!strcmp(q->integrator, "paper-vv") && !strcmp(q->method, r->method) &&
                !strcmp(q->where, !strcmp(r->where, "free-exact") ? "out-of-contact" : r->where)) {
                r->ratio = r->m.ns_med / q->m.ns_med;
                r->ratio_cpu = r->m.ns_cpu_med / q->m.ns_cpu_med;
            }
        }
    }
}

/* ---- the per-step benchmarks ------------------------------------------------------------------- */

static const vafm_integrator_type *s_integrator(int i)
{
    const vafm_integrator_type *const all[] = { vafm_integrator_gjf, vafm_integrator_baoab, vafm_integrator_paper_vv,
                                                vafm_integrator_brownian };
    return i >= 0 && i < 4 ? all[i] : NULL;
}

/* One kernel row: build, time, check the body stayed where it was put, release. */
static int s_kernel_row(s_bench *b, const vafm_params *p, double u_spr, int in_contact, int free_ou, const char *label,
                        const char *where)
{
    s_kwork *w = malloc(sizeof *w);
    if (!w || s_kwork_init(w, p, u_spr, in_contact)) {
        free(w);
        return -1;
    }
    w->free_ou = free_ou;
    s_meas m = s_measure(s_kwork_run, w);
    s_row *r = s_add(b, label, where, "kernel", free_ou ? w->ou.h : w->K.dt, m);
    if (r && (w->events || w->K.in_contact != in_contact))
        snprintf(r->note, sizeof r->note, "%llu contact changes", (unsigned long long)w->events);
    s_kwork_fini(w);
    free(w);
    return 0;
}

static int s_bench_kernel(s_bench *b)
{
    fprintf(stderr, "kernel (run() loops on a prepared kernel, support at rest):\n");
    for (int i = 0; s_integrator(i); i++) {
        const vafm_integrator_type *it = s_integrator(i);
        vafm_params p;
        s_scene_fig4_pressed(&p, it);
        /* in contact: support 5 R back from the contact point, about half way along the retract, on the
         * tensile stable branch (the instability is at u_spr* = -11.09); with the contact table (the
         * default) and with the exact Newton solve */
        if (s_kernel_row(b, &p, -5.0, 1, 0, it->name, "contact"))
            return -1;
        p.contact_table = 0;
        if (s_kernel_row(b, &p, -5.0, 1, 0, it->name, "contact-newton"))
            return -1;
        p.contact_table = 1;
        /* out of contact: support 20 R from the surface, integrator steps (as free_exact = 0) */
        if (s_kernel_row(b, &p, -20.0, 0, 0, it->name, "out-of-contact"))
            return -1;
        /* exact free propagation, once for the underdamped and once for the overdamped OU process */
        if ((it == vafm_integrator_gjf || it == vafm_integrator_brownian) &&
            s_kernel_row(b, &p, -20.0, 0, 1, it->overdamped ? "exact-ou-overdamped" : "exact-ou", "free-exact"))
            return -1;
    }
    return 0;
}

static int s_scene_row(s_bench *b, const vafm_params *p, int tune, const char *label, const char *where)
{
    s_swork w = { 0 };
    vafm_error err;
    if (vafm_sim_new(&w.sim, p, &err)) {
        fprintf(stderr, "bench_step: %s: %s\n", label, err.message);
        return -1;
    }
    w.tune = tune;
    w.time_s = vafm_units_scale(p).time_s;
    s_meas m = s_measure(s_swork_run, &w);
    /* the mean simulated time per step: dt for integrator steps, the free step for exact ones */
    double dt_step = w.sim_time / (double)w.steps;
    s_row *r = s_add(b, label, where, "scene", dt_step, m);
    if (r) {
        if (w.failed)
            snprintf(r->note, sizeof r->note, "a scene failed: %s", vafm_strerror(w.failed));
        else
            snprintf(r->note, sizeof r->note, "%.1f%% contact, %.1f%% exact-free steps",
                     100.0 * (double)w.steps_contact / (double)w.steps, 100.0 * (double)w.steps_free / (double)w.steps);
    }
    vafm_sim_destroy(&w.sim);
    return 0;
}

static int s_bench_scene(s_bench *b)
{
    fprintf(stderr, "scene (whole paper-fig4 curves pressed in / tunes 20 R off the surface, time / result.steps):\n");
    for (int i = 0; s_integrator(i); i++) {
        const vafm_integrator_type *it = s_integrator(i);
        vafm_params p;
        s_scene_fig4_pressed(&p, it);
        if (s_scene_row(b, &p, 0, it->name, "contact"))
            return -1;
        s_scene_fig4_far(&p, it, 0);
        if (s_scene_row(b, &p, 1, it->name, "out-of-contact"))
            return -1;
        if (it == vafm_integrator_gjf || it == vafm_integrator_brownian) {
            s_scene_fig4_far(&p, it, 1);
            if (s_scene_row(b, &p, 1, it->overdamped ? "exact-ou-overdamped" : "exact-ou", "free-exact"))
                return -1;
        }
    }
    return 0;
}

/* ---- real-time factor of the default scene ----------------------------------------------------- */

/* One real-time-factor run: the default scene with these numerics. */
typedef struct s_rtf_spec {
    const vafm_integrator_type *const *it;
    int noise;
    double omega_dt, omega_dt_far; /* far: 0 = no adaptive step */
    int well_exact;
} s_rtf_spec;

typedef struct s_rtf {
    s_rtf_spec spec;
    const char *integrator, *noise;
    double dt_s;
    uint64_t steps, steps_contact;
    double sim_s, wall_s, cpu_s;
    double pulloff_N; /* observable 2, a sanity check that the curve is a pull-off */
    int complete;     /* 0: cut at S_RTF_LIMIT_S, numbers are for the part run */
    int status;
} s_rtf;

static void s_rtf_numerics(const s_rtf *o, char *buf, size_t len)
{
    int n = snprintf(buf, len, "%.4g", o->spec.omega_dt);
    if (n > 0 && (size_t)n < len && o->spec.omega_dt_far > 0)
        n += snprintf(buf + n, len - (size_t)n, ", far %.3g", o->spec.omega_dt_far);
    if (n > 0 && (size_t)n < len && o->spec.well_exact)
        snprintf(buf + n, len - (size_t)n, ", well_exact");
}

/* One paper-fig1 curve (index 0), advanced in blocks so that an overlong one can be cut. */
static int s_rtf_run(s_rtf *o, const s_rtf_spec *spec)
{
    vafm_params p;
    vafm_error err;
    vafm_params_default(&p);
    p.integrator = *spec->it;
    p.noise = spec->noise;
    p.omega_dt = spec->omega_dt;
    p.omega_dt_far = spec->omega_dt_far;
    p.well_exact = spec->well_exact;
    memset(o, 0, sizeof *o);
    o->spec = *spec;
    o->integrator = p.integrator->name;
    o->noise = spec->noise == VAFM_NOISE_UNIFORM ? "uniform" : "gaussian";
    char lab[64];
    s_rtf_numerics(o, lab, sizeof lab);
    vafm_sim *s = NULL;
    if (vafm_sim_new(&s, &p, &err)) {
        fprintf(stderr, "bench_step: paper-fig1 %s omega_dt %s: %s\n", o->integrator, lab, err.message);
        return -1;
    }
    o->dt_s = vafm_sim_dt(s);
    fprintf(stderr, "  paper-fig1 %-8s %-8s omega_dt %s, dt %.3g s ... ", o->integrator, o->noise, lab, o->dt_s);
    s_clock t0 = s_now(), t1 = t0;
    int r = vafm_sim_curve_begin(s, 0);
    if (r == 0) {
        do {
            r = vafm_sim_advance(s, 1000, NULL, NULL);
            t1 = s_now();
        } while (r == 1 && t1.wall - t0.wall <= S_RTF_LIMIT_S);
    }
    vafm_curve_result res;
    vafm_sim_result(s, &res);
    o->complete = r == 0;
    o->status = r < 0 ? r : 0;
    o->steps = res.steps;
    o->steps_contact = res.steps_contact;
    o->sim_s = res.duration_s;
    o->wall_s = t1.wall - t0.wall;
    o->cpu_s = t1.cpu - t0.cpu;
    o->pulloff_N = res.pulloff_spring_N;
    fprintf(stderr, "%.2f s wall for %.1f s simulated (%s)\n", o->wall_s, o->sim_s,
            o->complete ? "complete" : o->status ? vafm_strerror(o->status) : "cut, extrapolated");
    vafm_sim_destroy(&s);
    return 0;
}

/* ---- output ------------------------------------------------------------------------------------ */

static void s_cpu_model(char *buf, size_t len)
{
    snprintf(buf, len, "unknown CPU");
    FILE *f = fopen("/proc/cpuinfo", "r");
    if (!f)
        return;
    char line[256];
    while (fgets(line, sizeof line, f)) {
        char *colon = strchr(line, ':');
        if (!strncmp(line, "model name", 10) && colon) {
            colon += 1 + (colon[1] == ' ');
            colon[strcspn(colon, "\n")] = '\0';
            snprintf(buf, len, "%s", colon);
            break;
        }
    }
    fclose(f);
}

static void s_write_csv(FILE *f, const s_bench *b)
{
    fprintf(f, "integrator,where,method,ns_per_step_median,ns_min,ns_max,ns_cpu_median,ratio_vs_paper_vv,"
               "ratio_cpu_vs_paper_vv,steps_per_s,dt_reduced\n");
    for (int i = 0; i < b->n; i++) {
        const s_row *r = &b->rows[i];
        fprintf(f, "%s,%s,%s,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.6g,%.6g\n", r->integrator, r->where, r->method,
                r->m.ns_med, r->m.ns_min, r->m.ns_max, r->m.ns_cpu_med, r->ratio, r->ratio_cpu, 1e9 / r->m.ns_med,
                r->dt);
    }
}

static void s_write_rtf_csv(FILE *f, const s_rtf *o, int n)
{
    fprintf(f, "integrator,noise,omega_dt,omega_dt_far,well_exact,dt_s,steps,steps_contact,simulated_s,wall_s,cpu_s,"
               "real_time_factor,rtf_cpu,ns_per_step,steps_per_s,complete,pulloff_spring_N\n");
    for (int i = 0; i < n; i++) {
        const s_rtf *x = &o[i];
        fprintf(f, "%s,%s,%.6g,%.6g,%d,%.6g,%llu,%llu,%.6g,%.6g,%.6g,%.6g,%.6g,%.4f,%.6g,%d,%.6g\n", x->integrator,
                x->noise, x->spec.omega_dt, x->spec.omega_dt_far, x->spec.well_exact, x->dt_s,
                (unsigned long long)x->steps, (unsigned long long)x->steps_contact, x->sim_s, x->wall_s, x->cpu_s,
                x->sim_s / x->wall_s, x->sim_s / x->cpu_s,
                1e9 * x->wall_s / (double)x->steps, (double)x->steps / x->wall_s, x->complete, x->pulloff_N);
    }
}

static void s_write_md(FILE *f, const s_bench *b, const s_rtf *o, int n_rtf)
{
    char cpu[128];
    s_cpu_model(cpu, sizeof cpu);
    fprintf(f, "## Step cost (bench_step)\n\n");
    fprintf(f, "Machine: %s, one thread; gcc %s; 1-minute load average %.2f before, %.2f after (other jobs share "
               "the machine when it is above ~0: then wall times include waiting, the CPU columns do not). Median of "
               "%d repetitions of >= %.1f s each (CLOCK_MONOTONIC; CPU: CLOCK_PROCESS_CPUTIME_ID). Scene: "
               "paper-fig4 (m~ = 0.01, k~ = 0.1, gamma~ = 0.229, kT~ = 0.01); paper-vv uses uniform noise (the "
               "paper's method, the baseline), the others gaussian.\n\n",
            cpu, __VERSION__, b->load0, b->load1, S_REPS, S_MIN_REP_S);
    fprintf(f, "- kernel: the integrator's run() loop on a prepared kernel, support at rest; in contact at "
               "u_spr = -5 (tensile, half way along the retract) with the tabulated JKR branch (contact_table = 1, "
               "the default), contact-newton: the same with the Newton solve every step (contact_table = 0); "
               "out of contact 20 R from the surface (integrator steps, as free_exact = 0); free-exact: one exact "
               "free-cantilever step (vafm_free_ou_steps, a chunk per call as the scene does).\n");
    fprintf(f, "- scene: whole curves through vafm_sim (pressed in 0.1 R, height trigger, retract through the "
               "pull-off) and thermal tunes 20 R off the surface, wall time / result.steps; includes sampling, "
               "phase logic and contact events.\n");
    fprintf(f, "- dt: reduced time per step (unit 1/eta). The overdamped integrator runs at its own, much "
               "smaller automatic dt (K_max dt/zeta = 2pi/40 with zeta = m eta = 0.01), so it needs ~15x more "
               "steps per curve; an exact free step covers several integrator steps.\n\n");
    fprintf(f, "| method | integrator | where | dt | ns/step (median) | min - max | CPU ns/step | vs paper-vv | "
               "vs paper-vv (CPU) | Msteps/s | note |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (int i = 0; i < b->n; i++) {
        const s_row *r = &b->rows[i];
        fprintf(f, "| %s | %s | %s | %.3g | %.2f | %.2f - %.2f | %.2f | %.2f | %.2f | %.1f | %s |\n", r->method,
                r->integrator, r->where, r->dt, r->m.ns_med, r->m.ns_min, r->m.ns_max, r->m.ns_cpu_med, r->ratio,
                r->ratio_cpu, 1e3 / r->m.ns_med, r->note);
    }
    fprintf(f, "\n## Real-time factor of the default scene (paper-fig1, one force curve)\n\n");
    fprintf(f, "Real-time factor = simulated time / wall time (one thread; \"by CPU time\": / process CPU time, what "
               "an unshared core gives), defaults otherwise (free_exact = 1, "
               "contact_table = 1). omega_dt = 2pi/40 = 0.157 is the paper's rule; \"far\" is the adaptive step "
               "(omega_dt_far) in contact away from the instability, well_exact the exact linearised contact-well "
               "step there.\n\n");
    fprintf(f, "| integrator | noise | omega_dt | dt (s) | steps | in contact | simulated (s) | wall (s) | CPU (s) | "
               "real-time factor | RTF by CPU time | ns/step | Msteps/s | pull-off (nN) |\n"
               "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    char lab[64];
    for (int i = 0; i < n_rtf; i++) {
        const s_rtf *x = &o[i];
        s_rtf_numerics(x, lab, sizeof lab);
        fprintf(f, "| %s | %s | %s | %.3g | %.3g | %.1f%% | %.2f | %.2f | %.2f | %.3g%s | %.3g | %.2f | %.1f | "
                   "%.4f |\n",
                x->integrator, x->noise, lab, x->dt_s, (double)x->steps,
                100.0 * (double)x->steps_contact / (double)x->steps, x->sim_s, x->wall_s, x->cpu_s,
                x->sim_s / x->wall_s, x->complete ? "" : x->status ? " (failed)" : " (cut)", x->sim_s / x->cpu_s,
                1e9 * x->wall_s / (double)x->steps, 1e-6 * (double)x->steps / x->wall_s, 1e9 * x->pulloff_N);
    }
    for (int i = 0; i < n_rtf; i++)
        if (!o[i].complete && !o[i].status) {
            s_rtf_numerics(&o[i], lab, sizeof lab);
            fprintf(f, "\n%s at omega_dt %s was cut after %.0f s of wall time: its real-time factor is the one "
                       "measured over the %.2f s simulated until then (%.3g steps at %.3g steps/s), not a full "
                       "curve's.\n",
                    o[i].integrator, lab, o[i].wall_s, o[i].sim_s, (double)o[i].steps,
                    (double)o[i].steps / o[i].wall_s);
        }
}

static int s_emit(const char *dir, const s_bench *b, const s_rtf *o, int n_rtf)
{
    FILE *f = bench_open("bench_step", dir, "bench_step.csv");
    if (!f)
        return -1;
    s_write_csv(f, b);
    fclose(f);
    if (!(f = bench_open("bench_step", dir, "bench_step_rtf.csv")))
        return -1;
    s_write_rtf_csv(f, o, n_rtf);
    fclose(f);
    if (!(f = bench_open("bench_step", dir, "bench_step.md")))
        return -1;
    s_write_md(f, b, o, n_rtf);
    fclose(f);
    s_write_md(stdout, b, o, n_rtf);
    return 0;
}

int main(int argc, char **argv)
{
    const char *dir = argc > 1 ? argv[1] : ".";
    static s_bench b; /* static: a few kB of rows, zero-initialised */
    b.load0 = bench_loadavg();
    if (s_bench_kernel(&b) || s_bench_scene(&b))
        return 1;
    s_ratios(&b);

    fprintf(stderr, "real-time factor (paper-fig1, one curve each):\n");
    s_rtf o[S_MAX_RTF];
    int n_rtf = 0;
    const double paper = 2.0 * M_PI / 40.0;
    /* the brief's four runs, then the core's two speed options for the in-contact part of a curve */
    const s_rtf_spec runs[] = {
        { &vafm_integrator_gjf, VAFM_NOISE_GAUSSIAN, paper, 0.0, 0 },
        { &vafm_integrator_gjf, VAFM_NOISE_GAUSSIAN, 0.5, 0.0, 0 },
        { &vafm_integrator_gjf, VAFM_NOISE_GAUSSIAN, 1.0, 0.0, 0 },
        { &vafm_integrator_paper_vv, VAFM_NOISE_UNIFORM, paper, 0.0, 0 },
        { &vafm_integrator_gjf, VAFM_NOISE_GAUSSIAN, paper, 1.0, 0 },
        { &vafm_integrator_gjf, VAFM_NOISE_GAUSSIAN, paper, 0.0, 1 },
        /* the cheapest step within 2 standard errors in the work-precision table, with the well step */
        { &vafm_integrator_gjf, VAFM_NOISE_GAUSSIAN, 0.6, 0.0, 1 },
    };
    for (size_t i = 0; i < sizeof runs / sizeof runs[0] && n_rtf < S_MAX_RTF; i++)
        if (s_rtf_run(&o[n_rtf], &runs[i]) == 0)
            n_rtf++;
    b.load1 = bench_loadavg();
    return s_emit(dir, &b, o, n_rtf) ? 1 : 0;
}
