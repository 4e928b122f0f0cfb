/* SPDX-License-Identifier: MIT */
/*
 * Replay of recorded force curves: the file is read once, on the control thread, into flat arrays (one
 * per channel, the selected curves back to back); the simulation thread then only walks a cursor over
 * them. Everything that can fail (I/O, damage, layout, memory) fails in vafmd_replay_prepare, where the
 * command can still be answered with an error; vafmd_replay_advance cannot fail.
 *
 * Choices (documented in protocol/wire.md, "replay"):
 * - samples are streamed as recorded, never resampled: a non-uniform time column is streamed in the
 *   extra channel time_s and paces the blocks; the header's sample rate is nominal;
 * - a channel is streamed only if every selected curve has it (the run has one channel list);
 * - deflection_m = force / spring constant (the layout has no deflection column), vDeflection_V =
 *   deflection_m / the curve's `sensitivity` attribute (absent from the stream without one);
 * - NaNs in the float channels are streamed as NaN; the time column must be finite and increasing
 *   (it paces the stream).
 */
#include "daemon/replay.h"
#include "core/channels.h"
#include "daemon/run_json.h"
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <jansson.h>
#include "h5/h5.h"
#include "vafm/wire.h"

typedef struct s_curve {
    uint64_t group; /* the curve's number in the file */
    size_t n;       /* samples */
    size_t off;     /* its first sample in the flat arrays */
    double sens;    /* sensitivity, m/V (NaN: none) */
    double t_off;   /* pass clock at the curve's start, s */
    size_t attr_bytes; /* its attributes in run.start, JSON-encoded (loading only) */
} s_curve;

struct vafmd_replay {
    size_t n_curves;
    s_curve *c;
    size_t total;      /* samples of one pass */
    double *height, *force, *defl, *tip, *time, *clock; /* flat; defl/tip/time NULL when not streamed */
    uint8_t *seg;
    unsigned mask;     /* streamed channels */
    double rate_Hz;    /* nominal rate: the first selected curve's */
    double pass_s;     /* duration of one pass, s */
    uint64_t passes;   /* 0: until abort */
    /* cursor (simulation thread) */
    uint64_t pass, run_sample;
    size_t cur, pos;   /* curve of the selection, sample within it */
    double clock_s;
    vafmd_replay_event ev[VAFMD_REPLAY_MAX_EVENTS];
    int n_ev;
};

void vafmd_replay_free(vafmd_replay **rp)
{
    if (!rp || !*rp)
        return;
    vafmd_replay *r = *rp;
    free(r->c);
    free(r->height);
    free(r->force);
    free(r->defl);
    free(r->tip);
    free(r->time);
    free(r->clock);
    free(r->seg);
    free(r);
    *rp = NULL;
}

unsigned vafmd_replay_channels(const vafmd_replay *rp) { return rp->mask; }
double vafmd_replay_rate_Hz(const vafmd_replay *rp) { return rp->rate_Hz; }
double vafmd_replay_clock_s(const vafmd_replay *rp) { return rp->clock_s; }

int vafmd_replay_take_events(vafmd_replay *rp, vafmd_replay_event *out, int max)
{
    int n = rp->n_ev < max ? rp->n_ev : max;
    memcpy(out, rp->ev, (size_t)n * sizeof *out);
    rp->n_ev = 0;
    return n;
}

int vafmd_replay_advance(vafmd_replay *rp, size_t max, vafm_sample_fn fn, void *user, double *sens)
{
    if (rp->passes && rp->pass >= rp->passes)
        return 0;
    const s_curve *c = &rp->c[rp->cur];
    if (max == 0)
        return 1;
    if (rp->pos == 0 && rp->n_ev < VAFMD_REPLAY_MAX_EVENTS)
        rp->ev[rp->n_ev++] = (vafmd_replay_event){ rp->run_sample, c->group, rp->cur, rp->pass, c->n };
    size_t n = c->n - rp->pos;
    if (n > max)
        n = max;
    size_t at = c->off + rp->pos;
    vafm_samples b = {
        .n = n,
        .first = rp->run_sample,
        .time_s = rp->time ? rp->time + at : NULL,
        .height_m = rp->height + at,
        .deflection_m = rp->defl ? rp->defl + at : NULL,
        .force_N = rp->force + at,
        .tip_m = rp->tip ? rp->tip + at : NULL,
        .segment = rp->seg + at,
    };
    *sens = c->sens;
    int stop = fn(user, &b);
    rp->pos += n;
    rp->run_sample += n;
    rp->clock_s = (double)rp->pass * rp->pass_s + c->t_off + rp->clock[at + n - 1];
    if (stop)
        return VAFM_EABORT;
    if (rp->pos == c->n) {
        rp->pos = 0;
        if (++rp->cur == rp->n_curves) {
            rp->cur = 0;
            rp->pass++;
            if (rp->passes && rp->pass >= rp->passes)
                return 0; /* together with the last sample: its block carries the LAST flag */
        }
    }
    return 1;
}

/* ---- loading (control thread) -------------------------------------------------------------------- */

/* Parse the selection: a string "all" | "A,B-C,D-" (inclusive ranges of group numbers, "D-" to the
 * last group) or an array of group numbers. Curves are named by their group number, as `vafm info` and
 * `vafm export` name them (a file may number its groups with gaps, or not from 0). Order and repetitions
 * are kept; out: positions in the reader. */
static int s_selection(json_t *v, const vafm_h5_reader *rd, uint64_t **out, size_t *n_out, vafmd_err *e)
{
    size_t count = vafm_h5_reader_count(rd);
    uint64_t g_first = vafm_h5_reader_group(rd, 0), g_last = vafm_h5_reader_group(rd, count - 1);
    size_t cap = VAFMD_REPLAY_MAX_CURVES, n = 0;
    uint64_t *sel = malloc(cap * sizeof *sel);
    if (!sel) {
        vafmd_err_set(e, VAFMD_E_INTERNAL, "curves", "out of memory");
        return -1;
    }
#define S_ADD_POS(pos)                                                                                        \
    do {                                                                                                      \
        if (n >= cap) {                                                                                       \
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "curves", "the selection has more than %u curves; replay " \
                          "at most %u at a time", VAFMD_REPLAY_MAX_CURVES, VAFMD_REPLAY_MAX_CURVES);         \
            goto fail;                                                                                        \
        }                                                                                                     \
        sel[n++] = (pos);                                                                                     \
    } while (0)
#define S_ADD_GROUP(x)                                                                                        \
    do {                                                                                                      \
        size_t pos_;                                                                                          \
        if (vafm_h5_reader_find(rd, (uint64_t)(x), &pos_)) {                                                  \
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "curves", "curve group '%" PRIu64 "' is not in the file "  \
                          "(its %zu groups are numbered %" PRIu64 " to %" PRIu64 "%s; vafm info lists them)",  \
                          (uint64_t)(x), count, g_first, g_last, g_last - g_first + 1 > count ? ", with gaps" : ""); \
            goto fail;                                                                                        \
        }                                                                                                     \
        S_ADD_POS(pos_);                                                                                      \
    } while (0)
    if (!v || (json_is_string(v) && !strcmp(json_string_value(v), "all"))) {
        for (size_t i = 0; i < count; i++)
            S_ADD_POS(i);
    } else if (json_is_array(v)) {
        size_t i;
        json_t *x;
        json_array_foreach(v, i, x) S_ADD_GROUP(json_integer_value(x)); /* the decoder checked the types */
    } else {
        const char *s = json_string_value(v);
        while (*s) {
            char *end;
            while (*s == ' ')
                s++;
            if (*s < '0' || *s > '9')
                goto syntax;
            unsigned long long a = strtoull(s, &end, 10), b = a;
            s = end;
            int range = *s == '-';
            if (range) {
                s++;
                if (*s >= '0' && *s <= '9') {
                    b = strtoull(s, &end, 10);
                    s = end;
                } else {
                    b = g_last;
                }
                if (b < a) {
                    vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "curves", "range %llu-%llu of \"curves\" is empty", a, b);
                    goto fail;
                }
                size_t before = n;
                for (size_t i = 0; i < count; i++) { /* every group in [a, b], in file order */
                    uint64_t g = vafm_h5_reader_group(rd, i);
                    if (g >= a && g <= b)
                        S_ADD_POS(i);
                }
                if (n == before) {
                    vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "curves", "no curve group in %llu-%llu (the file's "
                                  "groups are numbered %" PRIu64 " to %" PRIu64 ")", a, b, g_first, g_last);
                    goto fail;
                }
            } else {
                S_ADD_GROUP(a);
            }
            while (*s == ' ')
                s++;
            if (*s == ',')
                s++;
            else if (*s)
                goto syntax;
        }
        if (!n)
            goto syntax;
    }
#undef S_ADD_GROUP
#undef S_ADD_POS
    if (!n) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "curves", "the selection is empty");
        goto fail;
    }
    *out = sel;
    *n_out = n;
    return 0;
syntax:
    vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "curves", "\"curves\" must be \"all\", a list like \"0,3,5-9,12-\" "
                  "(inclusive ranges of group numbers; \"12-\": to the last group) or an array of group numbers");
fail:
    free(sel);
    return -1;
}

static int s_pos(double x) { return isfinite(x) && x > 0; }

/* A string attribute longer than VAFMD_REPLAY_MAX_ATTR_BYTES is refused (run.start carries it). */
static int s_attr_long(const char *v, const char *path, const char *where, const char *name, vafmd_err *e)
{
    size_t len = v ? strlen(v) : 0;
    if (len <= VAFMD_REPLAY_MAX_ATTR_BYTES)
        return 0;
    vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "path", "%.300s: %s attribute '%s' holds %zu bytes; replay takes at most "
                  "%u bytes an attribute (run.start carries them)", path, where, name, len, VAFMD_REPLAY_MAX_ATTR_BYTES);
    return -1;
}

/* The curve group's attributes as JSON (afmformats' names; absent ones left out); NULL with e set for
 * a string attribute over VAFMD_REPLAY_MAX_ATTR_BYTES or no memory. */
static json_t *s_attrs(const vafm_h5_meta *m, const char *path, uint64_t group, vafmd_err *e)
{
    json_t *o = json_object();
    if (!o) {
        vafmd_err_set(e, VAFMD_E_INTERNAL, "", "out of memory");
        return NULL;
    }
    const struct { const char *k; const char *v; } str[] = {
        { "imaging mode", m->imaging_mode }, { "feedback mode", m->feedback_mode }, { "instrument", m->instrument },
        { "software", m->software }, { "software version", m->software_version }, { "date", m->date },
        { "time", m->time }, { "session id", m->session_id }, { "curve id", m->curve_id },
    };
    char where[48];
    snprintf(where, sizeof where, "curve group '%" PRIu64 "':", group);
    for (size_t i = 0; i < sizeof str / sizeof *str; i++)
        if (str[i].v) {
            if (s_attr_long(str[i].v, path, where, str[i].k, e)) {
                json_decref(o);
                return NULL;
            }
            json_t *s = json_string(str[i].v); /* NULL for invalid UTF-8: leave it out */
            if (s)
                json_object_set_new(o, str[i].k, s);
        }
    const struct { const char *k; double v; } real[] = {
        { "spring constant", m->spring_constant_N_per_m }, { "sensitivity", m->sensitivity_m_per_V },
        { "setpoint", m->setpoint_N }, { "rate approach", m->rate_approach_Hz }, { "rate retract", m->rate_retract_Hz },
        { "speed approach", m->speed_approach_m_per_s }, { "speed retract", m->speed_retract_m_per_s },
        { "duration", m->duration_s }, { "duration approach", m->duration_approach_s },
        { "duration retract", m->duration_retract_s }, { "z range", m->z_range_m }, { "position x", m->position_x_m },
        { "position y", m->position_y_m }, { "grid center x", m->grid_center_x_m }, { "grid center y", m->grid_center_y_m },
        { "grid size x", m->grid_size_x_m }, { "grid size y", m->grid_size_y_m },
    };
    for (size_t i = 0; i < sizeof real / sizeof *real; i++)
        if (isfinite(real[i].v))
            json_object_set_new(o, real[i].k, json_real(real[i].v));
    const struct { const char *k; int64_t v; } in[] = {
        { "point count", m->point_count }, { "segment count", m->segment_count }, { "grid shape x", m->grid_shape_x },
        { "grid shape y", m->grid_shape_y }, { "grid index x", m->grid_index_x }, { "grid index y", m->grid_index_y },
    };
    for (size_t i = 0; i < sizeof in / sizeof *in; i++)
        if (in[i].v >= 0)
            json_object_set_new(o, in[i].k, json_integer((json_int_t)in[i].v));
    return o;
}

static json_t *s_num(double v) { return isfinite(v) ? json_real(v) : json_null(); }

static json_t *s_truth(const vafm_h5_truth *t)
{
    const vafm_curve_result *r = &t->result;
    json_t *o = json_object();
    json_object_set_new(o, "point", json_integer((json_int_t)t->point));
    json_object_set_new(o, "status", json_integer(t->status));
    json_object_set_new(o, "T_K", s_num(t->T_K));
    json_object_set_new(o, "v_m_per_s", s_num(t->v_m_per_s));
    json_object_set_new(o, "k_N_per_m", s_num(t->k_N_per_m));
    json_object_set_new(o, "flags", json_integer(r->flags));
    json_object_set_new(o, "pulloff_sampled_N", s_num(r->pulloff_sampled_N));
    json_object_set_new(o, "pulloff_spring_N", s_num(r->pulloff_spring_N));
    json_object_set_new(o, "detach_force_N", s_num(r->detach_force_N));
    json_object_set_new(o, "detach_height_m", s_num(r->detach_height_m));
    json_object_set_new(o, "detach_time_s", s_num(r->detach_time_s));
    json_object_set_new(o, "duration_s", s_num(r->duration_s));
    return o;
}

/* Grow every flat array to hold `need` samples. */
static int s_grow(vafmd_replay *r, size_t need, size_t *cap)
{
    if (need <= *cap)
        return 0;
    size_t nc = *cap ? *cap : 4096;
    while (nc < need)
        nc *= 2;
    if (nc > VAFMD_REPLAY_MAX_SAMPLES)
        nc = VAFMD_REPLAY_MAX_SAMPLES;
    double **d[] = { &r->height, &r->force, &r->defl, &r->tip, &r->time, &r->clock };
    for (size_t i = 0; i < sizeof d / sizeof *d; i++) {
        double *p = realloc(*d[i], nc * sizeof(double));
        if (!p)
            return -1;
        *d[i] = p;
    }
    uint8_t *s = realloc(r->seg, nc);
    if (!s)
        return -1;
    r->seg = s;
    *cap = nc;
    return 0;
}

/* Load curve `g` at the end of the flat arrays. Clock: the time from the curve's start until each
 * sample has been measured: recorded time − first time + one mean interval (vafm stamps a sample at
 * the middle of its interval: this gives (i + 1)/fs, the live stream's deadline), else the sum of
 * 1/rate of the samples' segments. */
static int s_load_curve(vafmd_replay *r, const char *path, const vafm_h5_curve *cv, s_curve *c, unsigned *mask,
                        double *rate_out, size_t *cap, vafmd_err *e)
{
    const vafm_h5_meta *m = &cv->meta;
    size_t n = cv->n;
    unsigned long long g = (unsigned long long)cv->group;
    if (r->total + n > VAFMD_REPLAY_MAX_SAMPLES) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "curves", "the selection holds more than %u samples (%zu up "
                      "to its curve %llu); replay holds at most %u samples (~100 MiB) in memory: select fewer "
                      "curves", VAFMD_REPLAY_MAX_SAMPLES, r->total + n, g, VAFMD_REPLAY_MAX_SAMPLES);
        return -1;
    }
    if (n == 0) {
        vafmd_err_set(e, VAFMD_E_BAD_FILE, "path", "%s: curve group '%llu' holds no samples (L7: n >= 1)", path, g);
        return -1;
    }
    double k = m->spring_constant_N_per_m, sens = m->sensitivity_m_per_V;
    double ra = m->rate_approach_Hz, rr = m->rate_retract_Hz;
    const struct { const char *name; double v; } pos[] = {
        { "spring constant", k }, { "sensitivity", sens }, { "rate approach", ra }, { "rate retract", rr },
    };
    for (size_t i = 0; i < sizeof pos / sizeof *pos; i++)
        if (!isnan(pos[i].v) && !s_pos(pos[i].v)) {
            vafmd_err_set(e, VAFMD_E_BAD_FILE, "path", "%s: curve group '%llu': attribute '%s' = %g is not a positive "
                          "number", path, g, pos[i].name, pos[i].v);
            return -1;
        }
    if (cv->time_s)
        for (size_t i = 0; i < n; i++)
            if (!isfinite(cv->time_s[i]) || (i && !(cv->time_s[i] > cv->time_s[i - 1]))) {
                vafmd_err_set(e, VAFMD_E_BAD_FILE, "path", "%s: /%llu/time: value %g at sample %zu is %s (L13: the time "
                              "column is finite and strictly increasing; it paces the replay)", path, g,
                              cv->time_s[i], i, isfinite(cv->time_s[i]) ? "not above the previous one" : "not finite");
                return -1;
            }
    /* nominal rate: the rate attributes, else the mean interval of the time column, else the duration */
    double fs = s_pos(ra) ? ra : s_pos(rr) ? rr : NAN;
    if (!s_pos(fs) && cv->time_s && n >= 2)
        fs = (double)(n - 1) / (cv->time_s[n - 1] - cv->time_s[0]);
    if (!s_pos(fs) && s_pos(m->duration_s))
        fs = (double)n / m->duration_s;
    if (!s_pos(fs)) {
        vafmd_err_set(e, VAFMD_E_BAD_FILE, "path", "%s: curve group '%llu' has no 'time' column, no 'rate approach'/'rate "
                      "retract' and no 'duration': its sample rate is unknown, so it cannot be paced", path, g);
        return -1;
    }
    if (s_grow(r, r->total + n, cap)) {
        vafmd_err_set(e, VAFMD_E_INTERNAL, "curves", "out of memory for %zu samples", r->total + n);
        return -1;
    }
    size_t o = r->total;
    const double *h = cv->height_piezo_m ? cv->height_piezo_m : cv->height_measured_m;
    memcpy(r->height + o, h, n * sizeof(double));
    memcpy(r->force + o, cv->force_N, n * sizeof(double));
    memcpy(r->seg + o, cv->segment, n);
    unsigned have = (1u << VAFM_CH_HEIGHT) | (1u << VAFM_CH_FORCE);
    if (s_pos(k)) {
        have |= 1u << VAFM_CH_DEFLECTION;
        for (size_t i = 0; i < n; i++) /* NaN force → NaN deflection */
            r->defl[o + i] = cv->force_N[i] / k;
        if (s_pos(sens))
            have |= 1u << VAFM_CH_VDEFLECTION;
    }
    if (cv->tip_position_m) {
        have |= 1u << VAFM_CH_TIP;
        memcpy(r->tip + o, cv->tip_position_m, n * sizeof(double));
    }
    if (cv->time_s) {
        have |= 1u << VAFM_CH_TIME;
        memcpy(r->time + o, cv->time_s, n * sizeof(double));
        for (size_t i = 0; i < n; i++)
            r->clock[o + i] = cv->time_s[i] - cv->time_s[0] + 1.0 / fs;
    } else {
        double ia = 1.0 / (s_pos(ra) ? ra : fs), ir = 1.0 / (s_pos(rr) ? rr : fs), t = 0;
        for (size_t i = 0; i < n; i++) /* dwell samples at the retract rate */
            r->clock[o + i] = t += cv->segment[i] == VAFM_SEG_APPROACH ? ia : ir;
    }
    if (!(r->clock[o + n - 1] <= 1e6)) { /* also NaN: deadlines are int64 ns from the run start */
        vafmd_err_set(e, VAFMD_E_BAD_FILE, "path", "%s: curve group '%llu' lasts %g s (from its %s): more than "
                      "the 1e6 s a replay paces", path, g, r->clock[o + n - 1], cv->time_s ? "time column" : "rates");
        return -1;
    }
    *mask &= have;
    *c = (s_curve){ cv->group, n, o, s_pos(sens) ? sens : NAN, r->pass_s, 0 };
    r->pass_s += r->clock[o + n - 1];
    r->total += n;
    *rate_out = fs;
    return 0;
}

/* Append a repetition of the loaded curve `src` at the end of the flat arrays (same samples, its own
 * place in the pass). */
static int s_repeat_curve(vafmd_replay *r, const s_curve *src, s_curve *c, size_t *cap, vafmd_err *e)
{
    size_t n = src->n, o = r->total;
    if (o + n > VAFMD_REPLAY_MAX_SAMPLES) { /* counted before anything was read: kept as a guard */
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "curves", "the selection holds more than %u samples; replay holds "
                      "at most %u samples (~100 MiB) in memory: select fewer curves", VAFMD_REPLAY_MAX_SAMPLES,
                      VAFMD_REPLAY_MAX_SAMPLES);
        return -1;
    }
    if (s_grow(r, o + n, cap)) {
        vafmd_err_set(e, VAFMD_E_INTERNAL, "curves", "out of memory for %zu samples", o + n);
        return -1;
    }
    double *d[] = { r->height, r->force, r->defl, r->tip, r->time, r->clock };
    for (size_t i = 0; i < sizeof d / sizeof *d; i++) /* src lies before o: no overlap */
        memcpy(d[i] + o, d[i] + src->off, n * sizeof(double));
    memcpy(r->seg + o, r->seg + src->off, n);
    *c = *src;
    c->off = o;
    c->t_off = r->pass_s;
    r->pass_s += r->clock[o + n - 1];
    r->total += n;
    return 0;
}

static const char *s_bad_code(int rc)
{
    return rc == VAFM_EIO ? VAFMD_E_IO : rc == VAFM_ENOMEM ? VAFMD_E_INTERNAL : VAFMD_E_BAD_FILE;
}

/* The reader's messages name the file, the object and what is wrong. */
static void s_file_err(vafmd_err *e, int rc, const char *path, const vafm_error *verr)
{
    if (verr->message[0])
        vafmd_err_set(e, s_bad_code(rc), "path", "cannot replay: %s", verr->message);
    else
        vafmd_err_set(e, s_bad_code(rc), "path", "cannot replay '%.300s': %s", path, vafm_strerror(rc));
}

int vafmd_replay_prepare(const vafmd_cmd *c, const vafmd_settings *set, uint64_t run_id, vafmd_replay **out,
                         char **start_json, size_t *block_n, vafmd_err *e)
{
    *out = NULL;
    *start_json = NULL;
    vafm_error verr;
    memset(&verr, 0, sizeof verr);
    vafm_h5_reader *rd = NULL;
    vafmd_replay *r = NULL;
    uint64_t *sel = NULL;
    size_t n_sel = 0, cap = 0;
    json_t *start = NULL, *curves = NULL;
    int rc = vafm_h5_reader_open(&rd, c->replay_path, &verr);
    if (rc) {
        s_file_err(e, rc, c->replay_path, &verr);
        goto fail;
    }
    size_t count = vafm_h5_reader_count(rd);
    if (!count) {
        vafmd_err_set(e, VAFMD_E_BAD_FILE, "path", "cannot replay '%.300s': the file holds no curves", c->replay_path);
        goto fail;
    }
    if (s_selection(c->replay_curves, rd, &sel, &n_sel, e))
        goto fail;
    if (!(r = calloc(1, sizeof *r)) || !(r->c = calloc(n_sel, sizeof *r->c))) {
        vafmd_err_set(e, VAFMD_E_INTERNAL, "", "out of memory");
        goto fail;
    }
    vafm_h5_provenance pv;
    vafm_h5_reader_provenance(rd, &pv);
    unsigned mask = vafm_channels_mask(VAFM_CHF_LIVE | VAFM_CHF_REPLAY); /* what a file can have */
    curves = json_array();
    uint64_t declared = 0;
    for (size_t i = 0; i < n_sel; i++) { /* the lengths first: nothing is read beyond the pass's limit */
        vafm_h5_curve cv;
        size_t j = 0;
        while (j < i && sel[j] != sel[i])
            j++;
        if (j < i) { /* a repetition: its length is known */
            cv.n = r->c[j].n;
            cv.group = r->c[j].group;
        } else if ((rc = vafm_h5_reader_curve_info(rd, (size_t)sel[i], &cv, &verr)) != 0) {
            s_file_err(e, rc, c->replay_path, &verr);
            goto fail;
        }
        r->c[i].n = cv.n;
        r->c[i].group = cv.group;
        declared += cv.n;
        if (declared > VAFMD_REPLAY_MAX_SAMPLES) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "curves", "the selection holds more than %u samples (%llu up "
                          "to its curve %llu); replay holds at most %u samples (~100 MiB) in memory: select fewer "
                          "curves", VAFMD_REPLAY_MAX_SAMPLES, (unsigned long long)declared,
                          (unsigned long long)cv.group, VAFMD_REPLAY_MAX_SAMPLES);
            goto fail;
        }
    }
    if (s_attr_long(pv.software, c->replay_path, "root", "software", e) ||
        s_attr_long(pv.software_version, c->replay_path, "root", "software version", e))
        goto fail;
    /* Each distinct curve is read, checked and encoded once; a repetition copies its samples and shares
     * its run.start entry (0.6.2 read and encoded it again per entry: 512 entries of one curve with a
     * 1 MiB attribute took the daemon to 1.55 GB). attr_bytes: the attributes' encoded size, summed per
     * entry as run.start spells them. */
    size_t attr_total = 0;
    for (size_t i = 0; i < n_sel; i++) {
        size_t j = 0;
        while (j < i && sel[j] != sel[i])
            j++;
        json_t *jc;
        size_t attr_bytes;
        if (j < i) {
            if (s_repeat_curve(r, &r->c[j], &r->c[i], &cap, e))
                goto fail;
            jc = json_array_get(curves, j);
            attr_bytes = r->c[j].attr_bytes;
            json_incref(jc);
        } else {
            vafm_h5_curve cv;
            rc = vafm_h5_reader_curve(rd, (size_t)sel[i], &cv, &verr);
            if (rc) {
                s_file_err(e, rc, c->replay_path, &verr);
                goto fail;
            }
            double fs;
            if (s_load_curve(r, c->replay_path, &cv, &r->c[i], &mask, &fs, &cap, e))
                goto fail;
            if (i == 0)
                r->rate_Hz = fs;
            json_t *attrs = s_attrs(&cv.meta, c->replay_path, cv.group, e);
            if (!attrs)
                goto fail;
            attr_bytes = json_dumpb(attrs, NULL, 0, JSON_COMPACT);
            jc = json_pack("{s:I,s:I,s:o,s:o}", "curve", (json_int_t)cv.group, "samples", (json_int_t)cv.n,
                           "sample_rate_Hz", json_real(fs), "attributes", attrs);
            if (!jc) {
                vafmd_err_set(e, VAFMD_E_INTERNAL, "", "out of memory");
                goto fail;
            }
            vafm_h5_truth t;
            if (pv.is_vafm && vafm_h5_reader_truth(rd, cv.group, &t) == 0)
                json_object_set_new(jc, "ground_truth", s_truth(&t));
            r->c[i].attr_bytes = attr_bytes;
        }
        json_array_append_new(curves, jc);
        r->n_curves = i + 1;
        attr_total += attr_bytes;
        if (attr_total > VAFMD_REPLAY_MAX_ATTRS_TOTAL) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "curves", "the selection's curve attributes take more than %u "
                          "bytes in run.start (%zu up to entry %zu, curve %llu); replay sends at most %u (8 MiB): "
                          "select fewer curves", VAFMD_REPLAY_MAX_ATTRS_TOTAL, attr_total, i,
                          (unsigned long long)r->c[i].group, VAFMD_REPLAY_MAX_ATTRS_TOTAL);
            goto fail;
        }
    }
    r->mask = mask;
    /* the flat arrays of channels that are not streamed are not needed */
    if (!(mask & (1u << VAFM_CH_DEFLECTION))) {
        free(r->defl);
        r->defl = NULL;
    }
    if (!(mask & (1u << VAFM_CH_TIP))) {
        free(r->tip);
        r->tip = NULL;
    }
    if (!(mask & (1u << VAFM_CH_TIME))) {
        free(r->time);
        r->time = NULL;
    }
    r->passes = c->replay_has_loop ? (uint64_t)c->replay_loop : 1;
    double speed = c->has_speed ? c->speed : set->speed;
    *block_n = vafmd_block_samples(r->rate_Hz, set->block_s);

    json_t *ch = vafmd_channels_json(mask);
    json_t *sel_j = json_array();
    for (size_t i = 0; i < n_sel; i++)
        json_array_append_new(sel_j, json_integer((json_int_t)vafm_h5_reader_group(rd, (size_t)sel[i])));
    json_t *vafm = json_null(), *scene = NULL;
    if (pv.is_vafm) {
        char fmt[32], seed[32];
        snprintf(fmt, sizeof fmt, "%d.%d", pv.format_major, pv.format_minor);
        snprintf(seed, sizeof seed, "%" PRIu64, pv.seed);
        json_t *grid = pv.grid_json ? json_loads(pv.grid_json, 0, NULL) : NULL;
        vafm = json_pack("{s:s,s:s,s:o,s:o}", "format_version", fmt, "seed", seed, "created",
                         pv.created ? json_string(pv.created) : json_null(), "grid", grid ? grid : json_null());
        if (pv.scene_json) {
            json_t *s = json_loads(pv.scene_json, 0, NULL);
            if (s)
                scene = s;
        }
    }
    json_t *sw = pv.software ? json_string(pv.software) : NULL, *swv = pv.software_version ? json_string(pv.software_version) : NULL;
    json_t *rp = json_object();
    json_t *pj = json_string(c->replay_path); /* NULL for a path that is not UTF-8 */
    json_object_set_new(rp, "path", pj ? pj : json_null());
    json_object_set_new(rp, "software", sw ? sw : json_null());
    json_object_set_new(rp, "software_version", swv ? swv : json_null());
    json_object_set_new(rp, "vafm", vafm);
    json_object_set_new(rp, "curves_in_file", json_integer((json_int_t)count));
    json_object_set_new(rp, "selection", sel_j);
    json_object_set_new(rp, "passes", r->passes ? json_integer((json_int_t)r->passes) : json_string("forever"));
    json_object_set_new(rp, "samples_per_pass", json_integer((json_int_t)r->total));
    json_object_set_new(rp, "duration_per_pass_s", json_real(r->pass_s));
    json_object_set_new(rp, "time_column", json_boolean(mask & (1u << VAFM_CH_TIME)));
    json_object_set_new(rp, "curves", curves);
    curves = NULL;

    start = json_object();
    json_object_set_new(start, "protocol_version", json_integer(VAFM_WIRE_PROTOCOL_VERSION));
    json_object_set_new(start, "run_id", json_integer((json_int_t)run_id));
    json_object_set_new(start, "client_run_id", c->client_run_id[0] ? json_string(c->client_run_id) : json_null());
    json_object_set_new(start, "kind", json_string("replay"));
    json_object_set_new(start, "index", json_null());
    json_object_set_new(start, "sample_rate_Hz", json_real(r->rate_Hz));
    json_object_set_new(start, "block_samples", json_integer((json_int_t)*block_n));
    json_object_set_new(start, "dt_s", json_null());
    json_object_set_new(start, "sensitivity_m_per_V", s_num(r->c[0].sens));
    json_object_set_new(start, "speed", json_real(speed));
    json_object_set_new(start, "free_run", json_boolean(set->free_run));
    json_object_set_new(start, "channels", ch);
    json_object_set_new(start, "segments", json_pack("{s:i,s:i,s:i,s:i}", "approach", VAFM_SEG_APPROACH, "retract",
                                                     VAFM_SEG_RETRACT, "dwell", VAFM_SEG_DWELL, "tune", VAFM_SEG_TUNE));
    if (scene) /* other programs' files have no scene: the key is left out (clients default it) */
        json_object_set_new(start, "scene", scene);
    json_object_set_new(start, "replay", rp);
    *start_json = json_dumps(start, JSON_COMPACT);
    json_decref(start);
    if (!*start_json) {
        vafmd_err_set(e, VAFMD_E_INTERNAL, "", "cannot encode the run.start message");
        goto fail;
    }
    free(sel);
    vafm_h5_reader_destroy(&rd);
    *out = r;
    return 0;
fail:
    json_decref(curves);
    free(sel);
    vafm_h5_reader_destroy(&rd);
    vafmd_replay_free(&r);
    return -1;
}
