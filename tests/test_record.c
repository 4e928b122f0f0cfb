/* SPDX-License-Identifier: MIT */
/*
 * The recording layer: the statistics (moments against a two-pass computation, the one pull-off rule)
 * and the recorder (create / resume / overwrite, the id rule, ground truth kept and appended, flushes
 * after every curve or from the flusher thread, what a reader gets back bit for bit).
 */
#include <inttypes.h>
#include <math.h>
#include <stdint.h>
#include <unistd.h>
#include "harness.h"
#include "vafm/campaign.h"
#include "campaign_spec.h"
#include "h5/h5.h"
#include "record/record.h"
#include "record/scene.h"
#include "vafm/stats.h"

static void test_moments(void)
{
    /* a fixed skewed sequence: x_i = (i mod 7)^2 + 0.1 i, i < 1000; two-pass reference */
    enum { N = 1000 };
    double x[N], m = 0, m2 = 0, m3 = 0;
    vafm_moments mo = { 0 };
    for (int i = 0; i < N; i++) {
        x[i] = (double)((i % 7) * (i % 7)) + 0.1 * i;
        vafm_moments_add(&mo, x[i]);
        m += x[i];
    }
    m /= N;
    for (int i = 0; i < N; i++) {
        m2 += (x[i] - m) * (x[i] - m);
        m3 += (x[i] - m) * (x[i] - m) * (x[i] - m);
    }
    ENSURE(mo.n == N);
    ENSURE_REL(mo.mean, m, 1e-13);
    ENSURE_REL(vafm_moments_sd(&mo), sqrt(m2 / (N - 1)), 1e-12);
    ENSURE_REL(vafm_moments_sem(&mo), sqrt(m2 / (N - 1)) / sqrt((double)N), 1e-12);
    ENSURE_REL(vafm_moments_skewness(&mo), sqrt((double)N) * m3 / pow(m2, 1.5), 1e-10);
    vafm_moments one = { 0 };
    vafm_moments_add(&one, 3.0);
    ENSURE(isnan(vafm_moments_sd(&one)) && isnan(vafm_moments_skewness(&one)) && one.mean == 3.0);
}

static void test_pulloff_rule(void)
{
    vafm_curve_result r;
    memset(&r, 0, sizeof r);
    r.pulloff_spring_N = 1e-9;
    ENSURE(vafm_stats_is_pulloff(0, &r));
    ENSURE(!vafm_stats_is_pulloff(VAFM_EUNSTABLE, &r));
    r.flags = VAFM_CURVE_RECONTACT;
    ENSURE(vafm_stats_is_pulloff(0, &r));
    int excluded[] = { VAFM_CURVE_NO_CONTACT, VAFM_CURVE_EARLY_DETACH, VAFM_CURVE_NO_DETACH, VAFM_CURVE_NO_TRIGGER };
    for (size_t i = 0; i < sizeof excluded / sizeof excluded[0]; i++) {
        r.flags = excluded[i] | VAFM_CURVE_RECONTACT;
        ENSURE_MSG(!vafm_stats_is_pulloff(0, &r), "flag %d", excluded[i]);
    }
    /* the point table counts flags of every curve, moments only of pull-offs, failures apart */
    vafm_point_stats st;
    memset(&st, 0, sizeof st);
    r.flags = 0;
    vafm_point_stats_add(&st, 0, &r);
    r.flags = VAFM_CURVE_NO_TRIGGER;
    vafm_point_stats_add(&st, 0, &r);
    vafm_point_stats_add(&st, VAFM_EUNSTABLE, &r);
    ENSURE(st.curves == 3 && st.used == 1 && st.failed == 1 && st.flag_count[3] == 1);
    ENSURE(st.obs[VAFM_OBS_PULLOFF_SPRING].n == 1 && st.obs[VAFM_OBS_PULLOFF_SPRING].mean == 1e-9);
    ENSURE(!strcmp(vafm_stats_observable(VAFM_OBS_DETACH_EQ_FORCE)->name, "detach_eq_force_N"));
    ENSURE(vafm_stats_observable(VAFM_OBS_COUNT) == NULL && isnan(vafm_stats_value(&r, -1)));
    vafm_params p;
    vafm_params_default(&p);
    ENSURE_REL(vafm_stats_f_jkr_N(&p), 1.5 * M_PI * p.gamma_J_per_m2 * p.R_m, 1e-15);
}

static void test_ids(void)
{
    char s[48], c[96];
    vafm_record_ids(7, 12, 0, NULL, s, sizeof s, c, sizeof c);
    ENSURE(!strcmp(s, "seed 7") && !strcmp(c, "index 12"));
    vafm_record_ids(7, 12, 3, "abc", s, sizeof s, c, sizeof c);
    ENSURE(!strcmp(c, "run 3 index 12 client abc"));
    vafm_record_ids(UINT64_MAX, 0, 5, "", s, sizeof s, c, sizeof c);
    ENSURE(!strcmp(s, "seed 18446744073709551615") && !strcmp(c, "run 5 index 0"));
}

/* A small campaign recorded through the recorder. */
typedef struct s_rec_run {
    vafm_recorder *rec;
    uint64_t appended;
    int err;
    uint64_t durable;
} s_rec_run;

static int s_rec_cb(void *user, const vafm_campaign_curve *c)
{
    s_rec_run *rr = user;
    vafm_record_curve rc = { .samples = &c->samples, .params = c->params, .result = &c->result,
                             .point = c->point, .sensitivity_m_per_V = NAN };
    vafm_error e;
    if ((rr->err = vafm_recorder_append(rr->rec, &rc, &e)) != 0) {
        fprintf(stderr, "append: %s\n", e.message);
        return 1;
    }
    rr->appended++;
    return 0;
}

static void s_on_durable(void *user, uint64_t n)
{
    ((s_rec_run *)user)->durable = n;
}

static void s_scene(vafm_params *p)
{
    vafm_preset_apply(p, "paper-fig4", NULL);
    p->T_K = 0; /* deterministic and fast */
    p->v_approach_m_per_s = p->v_retract_m_per_s = 1e-3;
}

static int s_run_campaign(const char *path, int mode, double interval, uint64_t n, uint64_t first, s_rec_run *rr)
{
    vafm_params p;
    s_scene(&p);
    double T[2] = { 0, 1e5 };
    vafm_campaign_spec sp = t_campaign_spec(T, 2, NULL, 0, n);
    sp.threads = 2;
    sp.keep_samples = 1;
    vafm_recorder_opts o;
    vafm_recorder_opts_default(&o);
    o.mode = mode;
    o.flush_interval_s = interval;
    o.on_durable = s_on_durable;
    o.user = rr;
    vafm_error e;
    memset(&e, 0, sizeof e);
    int rc = vafm_recorder_open(&rr->rec, path, &o, &p, &sp, &e);
    if (rc) {
        fprintf(stderr, "open: %s\n", e.message);
        return rc;
    }
    uint64_t have = vafm_recorder_count(rr->rec);
    sp.first_curve = have > first ? have : first;
    rc = vafm_campaign_run(&p, &sp, s_rec_cb, rr, &e);
    vafm_recorder_report rep;
    int cr = vafm_recorder_close(&rr->rec, &rep, &e);
    ENSURE(rr->rec == NULL && rep.appended == rr->appended && rep.kept == have && rep.flushes >= 1);
    return rc ? rc : cr;
}

/* A new file of a 2-point campaign with n curves a point, flushed after every curve. */
static int s_fresh_campaign(const char *path, uint64_t n, s_rec_run *rr)
{
    unlink(path);
    memset(rr, 0, sizeof *rr);
    return s_run_campaign(path, VAFM_RECORD_CREATE, 0.0, n, 0, rr);
}

static void test_recorder(void)
{
    const char *path = "t_record.h5";
    s_rec_run a;
    ENSURE(s_fresh_campaign(path, 3, &a) == 0);
    ENSURE(a.appended == 6 && a.durable == 6);
    /* create refuses an existing file; resume of a complete file appends nothing */
    s_rec_run b;
    memset(&b, 0, sizeof b);
    ENSURE(s_run_campaign(path, VAFM_RECORD_CREATE, 0.0, 3, 0, &b) != 0);
    memset(&b, 0, sizeof b);
    ENSURE(s_run_campaign(path, VAFM_RECORD_RESUME, 0.5, 3, 0, &b) == 0 && b.appended == 0);
    /* what a reader sees: ids by the rule, truth rows numbered by group, the grid point */
    vafm_h5_reader *r = NULL;
    vafm_error e;
    ENSURE(vafm_h5_reader_open(&r, path, &e) == 0);
    if (r) {
        ENSURE(vafm_h5_reader_count(r) == 6);
        for (size_t i = 0; i < vafm_h5_reader_count(r); i++) {
            vafm_h5_curve c;
            vafm_h5_truth t;
            char want[32];
            snprintf(want, sizeof want, "index %zu", i);
            ENSURE(vafm_h5_reader_curve(r, i, &c, &e) == 0);
            ENSURE(c.meta.curve_id && !strcmp(c.meta.curve_id, want));
            ENSURE(c.meta.session_id && !strcmp(c.meta.session_id, "seed 1"));
            ENSURE(vafm_h5_reader_truth(r, i, &t) == 0 && t.point == i / 3 && t.result.index == i);
        }
        vafm_h5_reader_destroy(&r);
    }
    /* a campaign cut after 2 curves and resumed with the flusher thread gives the same file content */
    const char *p2 = "t_record_resumed.h5";
    unlink(p2);
    s_rec_run c1, c2;
    memset(&c1, 0, sizeof c1);
    memset(&c2, 0, sizeof c2);
    ENSURE(s_run_campaign(p2, VAFM_RECORD_CREATE, 1e-3, 1, 0, &c1) == 0); /* 2 curves: one per point */
    /* the same file as a 3-per-point campaign cannot resume (another grid) */
    ENSURE(s_run_campaign(p2, VAFM_RECORD_RESUME, 1e-3, 3, 0, &c2) != 0);
    ENSURE(s_run_campaign(p2, VAFM_RECORD_OVERWRITE, 1e-3, 3, 0, &c2) == 0 && c2.appended == 6 && c2.durable == 6);
    vafm_h5_reader *ra = NULL, *rb = NULL;
    ENSURE(vafm_h5_reader_open(&ra, path, &e) == 0 && vafm_h5_reader_open(&rb, p2, &e) == 0);
    if (ra && rb)
        for (size_t i = 0; i < 6; i++) {
            vafm_h5_curve x, y;
            ENSURE(vafm_h5_reader_curve(ra, i, &x, &e) == 0);
            size_t n = x.n;
            double *f = malloc(n * sizeof *f);
            if (f)
                memcpy(f, x.force_N, n * sizeof *f);
            ENSURE(vafm_h5_reader_curve(rb, i, &y, &e) == 0);
            ENSURE(f && y.n == n && !memcmp(f, y.force_N, n * sizeof *f));
            vafm_h5_truth ta, tb;
            ENSURE(!vafm_h5_reader_truth(ra, i, &ta) && !vafm_h5_reader_truth(rb, i, &tb) &&
                   ta.result.pulloff_spring_N == tb.result.pulloff_spring_N);
            free(f);
        }
    vafm_h5_reader_destroy(&ra);
    vafm_h5_reader_destroy(&rb);
    /* bad options name their field */
    vafm_recorder *rec = NULL;
    vafm_recorder_opts o;
    vafm_recorder_opts_default(&o);
    o.flush_interval_s = -1;
    memset(&e, 0, sizeof e);
    ENSURE(vafm_recorder_open(&rec, "t_record_bad.h5", &o, NULL, NULL, &e) == VAFM_EINVAL && rec == NULL);
    ENSURE(!strcmp(e.field, "flush_interval_s"));
    ENSURE(access("t_record_bad.h5", F_OK) != 0);
    ENSURE(vafm_recorder_close(&rec, NULL, NULL) == 0); /* NULL-safe */
    unlink(path);
    unlink(p2);
}

static void test_campaign_validate(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "paper-fig4", NULL);
    double T[3] = { 10, -5, 20 };
    vafm_campaign_spec sp = t_campaign_spec(T, 3, NULL, 0, 1);
    size_t bad = 99;
    vafm_error e;
    memset(&e, 0, sizeof e);
    ENSURE(vafm_campaign_validate(&p, &sp, &bad, &e) == VAFM_EINVAL);
    ENSURE(bad == 1 && !strcmp(e.field, "T_K") && strstr(e.message, "grid point 1"));
    sp.n_T = 1;
    ENSURE(vafm_campaign_validate(&p, &sp, &bad, &e) == 0);
}

/* One set of JSON rules for scenes: strict types, preset first, errors naming the key. */
static void test_scene_json(void)
{
    vafm_params p, q;
    vafm_error e;
    vafm_params_default(&p);
    ENSURE(vafm_scene_parse(&p, "{\"k_N_per_m\": 0.2, \"preset\": \"paper-fig4\", \"seed\": \"18446744073709551615\"}",
                            "t", &e) == 0);
    vafm_preset_apply(&q, "paper-fig4", NULL);
    ENSURE(p.k_N_per_m == 0.2 && p.seed == UINT64_MAX && p.R_m == q.R_m);
    /* the stricter rules: booleans are true/false, seeds non-negative whole numbers, choices strings */
    static const char *bad[] = { "{\"free_exact\": 1}", "{\"seed\": -1}", "{\"seed\": 1.5}", "{\"seed\": \"12a\"}",
                                 "{\"integrator\": 3}", "{\"k_N_per_m\": \"0.2\"}", "[1]", "{\"k_N_per_m\": 1e400}" };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        memset(&e, 0, sizeof e);
        vafm_params_default(&p);
        int rc = vafm_scene_parse(&p, bad[i], "t", &e);
        ENSURE_MSG(rc != 0 && e.message[0], "%s accepted", bad[i]);
    }
    memset(&e, 0, sizeof e);
    ENSURE(vafm_scene_parse(&p, "{\"free_exact\": 1}", "t", &e) == VAFM_EINVAL && !strcmp(e.field, "free_exact"));
    ENSURE(strstr(e.message, "true or false") != NULL);
    ENSURE(vafm_scene_parse(&p, "{\"nope\": 1}", "t", &e) == VAFM_ENOTFOUND && !strcmp(e.field, "nope"));
    /* params → JSON → params is exact */
    vafm_preset_apply(&q, "paper-fig1", NULL);
    q.k_N_per_m = 0.1 + 0.2; /* not a short decimal */
    static char js[16384];
    vafm_params_default(&p);
    ENSURE(vafm_params_to_json(&q, js, sizeof js) > 0);
    ENSURE(vafm_scene_parse(&p, js, "t", &e) == 0 && p.k_N_per_m == q.k_N_per_m && p.T_K == q.T_K);
    /* a scene file that is not a regular file is refused at once (a FIFO would block) */
    ENSURE(vafm_scene_load_file(&p, ".", NULL, 0, &e) == VAFM_EIO);
}

/* The scene and grid a file was written with come back through vafm_scene_from_h5. */
static void test_scene_from_h5(void)
{
    const char *path = "t_record_scene.h5";
    s_rec_run a;
    ENSURE(s_fresh_campaign(path, 2, &a) == 0);
    vafm_h5_reader *r = NULL;
    vafm_error e;
    ENSURE(vafm_h5_reader_open(&r, path, &e) == 0);
    vafm_params p, want;
    vafm_scene_grid g;
    s_scene(&want);
    ENSURE(vafm_scene_from_h5(r, path, &p, &g, &e) == 0);
    ENSURE(p.k_N_per_m == want.k_N_per_m && p.v_retract_m_per_s == want.v_retract_m_per_s && p.T_K == want.T_K);
    ENSURE(g.n_T == 2 && g.T_K && g.T_K[1] == 1e5 && g.curves_per_point == 2);
    vafm_scene_grid_free(&g);
    vafm_h5_reader_destroy(&r);
    unlink(path);
    ENSURE(vafm_scene_from_h5(NULL, path, &p, NULL, &e) == VAFM_ENOTFOUND);
}

int main(void)
{
    RUN_TEST(test_scene_json);
    RUN_TEST(test_scene_from_h5);
    RUN_TEST(test_moments);
    RUN_TEST(test_pulloff_rule);
    RUN_TEST(test_ids);
    RUN_TEST(test_campaign_validate);
    RUN_TEST(test_recorder);
    return harness_done();
}
