/* SPDX-License-Identifier: MIT */
/*
 * The scene parameters (params.h, units.h): the field table every front end reads, the presets, text
 * set/get, JSON export, the refusal of bad values (each naming its field and range), the unit
 * conversion, the paper's Fig. 1 scene in SI (physics notes, "Units") and the status strings.
 *
 * Nothing here is stochastic; all checks are exact or at rounding level.
 */
#include "harness.h"

#include <float.h>
#include <inttypes.h>
#include <stddef.h>

#include "vafm/common.h"
#include "vafm/contact.h"
#include "vafm/integrator.h"
#include "vafm/params.h"
#include "vafm/units.h"
#include "vafm/version.h"
#include "vafm/sim.h"

/* REAL fields that are dimensionless by design (a ratio): everything else must carry an SI unit. */
static int t_dimensionless(const char *name)
{
    return !strcmp(name, "omega_dt") || !strcmp(name, "omega_dt_far") || !strcmp(name, "near_barrier_kT") ||
           !strcmp(name, "Q") || !strcmp(name, "piezo_hysteresis") || !strcmp(name, "piezo_creep");
}

/* The range as the library formats it in its messages ("[%.6g, %.6g]"). */
static void t_range_text(const vafm_param_info *f, char *buf, size_t len)
{
    snprintf(buf, len, "[%.6g, %.6g]", f->min, f->max);
}

static double t_get_real(const vafm_params *p, const char *name)
{
    char buf[128];
    if (vafm_params_get(p, name, buf, sizeof buf))
        return NAN;
    return strtod(buf, NULL);
}

static void test_field_table(void)
{
    const int n = vafm_params_field_count();
    ENSURE(n >= 20);
    ENSURE(vafm_params_field_at(-1) == NULL);
    ENSURE(vafm_params_field_at(n) == NULL);
    for (int i = 0; i < n; i++) {
        const vafm_param_info *f = vafm_params_field_at(i);
        ENSURE(f != NULL);
        if (!f)
            continue;
        ENSURE_MSG(f->name && f->name[0], "row %d has no name", i);
        ENSURE_MSG(f->doc && strlen(f->doc) >= 10, "%s: doc missing", f->name);
        ENSURE_MSG(f->unit != NULL, "%s: unit is NULL", f->name);
        ENSURE_MSG(vafm_params_field_find(f->name) == f, "%s: find does not return its own row", f->name);
        for (int j = 0; j < i; j++)
            ENSURE_MSG(strcmp(vafm_params_field_at(j)->name, f->name) != 0, "duplicate field %s", f->name);
        switch (f->kind) {
        case VAFM_PARAM_REAL:
            ENSURE_MSG(f->min <= f->max, "%s: min %g > max %g", f->name, f->min, f->max);
            ENSURE_MSG(isfinite(f->min) && isfinite(f->max), "%s: range not finite", f->name);
            if (t_dimensionless(f->name))
                ENSURE_MSG(f->unit[0] == '\0', "%s is dimensionless but has unit '%s'", f->name, f->unit);
            else
                ENSURE_MSG(f->unit[0] != '\0', "%s has no unit", f->name);
            break;
        case VAFM_PARAM_CHOICE:
            ENSURE_MSG(f->choices && strchr(f->choices, '|'), "%s: choices '%s'", f->name,
                       f->choices ? f->choices : "(null)");
            break;
        case VAFM_PARAM_SEED:
        case VAFM_PARAM_BOOL:
            ENSURE_MSG(f->min <= f->max, "%s: min > max", f->name);
            break;
        case VAFM_PARAM_INT:
            ENSURE_MSG(f->min <= f->max && f->min == floor(f->min) && f->max == floor(f->max), "%s: range", f->name);
            ENSURE_MSG(f->unit[0] != '\0', "%s has no unit", f->name);
            break;
        default: ENSURE_MSG(0, "%s: unknown kind %d", f->name, f->kind);
        }
    }
    ENSURE(vafm_params_field_find("no_such_field") == NULL);
    ENSURE(vafm_params_field_find(NULL) == NULL);
    /* the fields the rest of the code relies on exist */
    const char *must[] = {"E_star_Pa", "R_m", "gamma_J_per_m2", "contact", "k_N_per_m", "m_kg", "eta_per_s",
                          "T_K", "v_approach_m_per_s", "v_retract_m_per_s", "start_height_m", "trigger",
                          "setpoint_N", "dwell_s", "sample_rate_Hz", "integrator", "noise", "dt_s",
                          "omega_dt", "free_exact", "seed", "antialias"};
    for (size_t i = 0; i < sizeof must / sizeof must[0]; i++)
        ENSURE_MSG(vafm_params_field_find(must[i]) != NULL, "field %s missing", must[i]);
}

static void test_presets(void)
{
    const int np = vafm_preset_count();
    ENSURE(np >= 3);
    ENSURE(vafm_preset_name(np) == NULL && vafm_preset_name(-1) == NULL);
    for (int i = 0; i < np; i++) {
        const char *name = vafm_preset_name(i);
        ENSURE(name != NULL);
        ENSURE(vafm_preset_description(i) && vafm_preset_description(i)[0]);
        vafm_params p;
        vafm_error err = {0};
        ENSURE(vafm_preset_apply(&p, name, &err) == 0);
        int r = vafm_params_validate(&p, &err);
        ENSURE_MSG(r == 0, "preset %s does not validate: %s (%s)", name, err.field, err.message);
        /* every REAL value of the preset lies in its field's range */
        for (int j = 0; j < vafm_params_field_count(); j++) {
            const vafm_param_info *f = vafm_params_field_at(j);
            if (f->kind != VAFM_PARAM_REAL)
                continue;
            double v = t_get_real(&p, f->name);
            ENSURE_MSG(v >= f->min && v <= f->max, "preset %s: %s = %g outside [%g, %g]", name, f->name, v, f->min,
                       f->max);
        }
    }
    vafm_params d, f1;
    vafm_params_default(&d);
    ENSURE(vafm_preset_apply(&f1, "paper-fig1", NULL) == 0);
    ENSURE(memcmp(&d, &f1, sizeof d) == 0); /* the default is paper-fig1 */
    ENSURE(vafm_params_validate(&d, NULL) == 0);

    /* the default step of every preset is the paper's, named "paper" (docs/speed-and-accuracy.md, "The
     * default step"); --omega_dt 0.157 is the same step to three digits */
    for (int i = 0; i < np; i++) {
        vafm_params p;
        vafm_preset_apply(&p, vafm_preset_name(i), NULL);
        ENSURE_MSG(p.omega_dt == VAFM_OMEGA_DT_PAPER, "preset %s: omega_dt %g", vafm_preset_name(i), p.omega_dt);
    }
    ENSURE(vafm_params_set(&d, "omega_dt", "0.6", NULL) == 0 && d.omega_dt == 0.6);
    ENSURE(vafm_params_set(&d, "omega_dt", "paper", NULL) == 0 && d.omega_dt == 2.0 * M_PI / 40.0);
    ENSURE(vafm_params_set(&d, "omega_dt", "0.157", NULL) == 0 && fabs(d.omega_dt - VAFM_OMEGA_DT_PAPER) < 1e-3);
    ENSURE(vafm_params_set(&d, "omega_dt_far", "paper", NULL) == VAFM_EINVAL); /* the name is omega_dt's only */
    vafm_params_default(&d);

    vafm_error err = {0};
    ENSURE(vafm_preset_apply(&d, "no-such-preset", &err) == VAFM_ENOTFOUND);
    ENSURE(err.code == VAFM_ENOTFOUND);
    ENSURE(strstr(err.message, "no-such-preset") != NULL);
    ENSURE(strstr(err.message, "paper-fig1") != NULL); /* names the known ones */
    /* ... all of them, from the preset table in its order (a new preset is named without a second list) */
    char known[512] = "";
    for (int i = 0; i < vafm_preset_count(); i++)
        snprintf(known + strlen(known), sizeof known - strlen(known), "%s%s", i ? ", " : "", vafm_preset_name(i));
    char want[700];
    snprintf(want, sizeof want, "unknown preset 'no-such-preset' (known: %s)", known);
    ENSURE_MSG(!strcmp(err.message, want), "%s", err.message);
    ENSURE(vafm_params_validate(NULL, &err) == VAFM_EINVAL);
}

/* get → set → get gives identical text for every field of every preset (REAL with %.17g is exact). */
static void test_set_get_roundtrip(void)
{
    for (int i = 0; i < vafm_preset_count(); i++) {
        vafm_params p, q;
        vafm_preset_apply(&p, vafm_preset_name(i), NULL);
        vafm_preset_apply(&q, "paper-fig1", NULL);
        for (int j = 0; j < vafm_params_field_count(); j++) {
            const vafm_param_info *f = vafm_params_field_at(j);
            char a[128], b[128];
            ENSURE(vafm_params_get(&p, f->name, a, sizeof a) == 0);
            vafm_error err = {0};
            int r = vafm_params_set(&q, f->name, a, &err);
            ENSURE_MSG(r == 0, "%s: set('%s') = %d: %s", f->name, a, r, err.message);
            ENSURE(vafm_params_get(&q, f->name, b, sizeof b) == 0);
            ENSURE_MSG(!strcmp(a, b), "%s: '%s' != '%s'", f->name, a, b);
        }
        /* after copying every field through text, q is p (reserved bytes are zero in both) */
        ENSURE_MSG(memcmp(&p, &q, sizeof p) == 0, "preset %s: text copy differs", vafm_preset_name(i));
    }
    /* every choice of every CHOICE field round-trips */
    vafm_params p;
    vafm_params_default(&p);
    for (int j = 0; j < vafm_params_field_count(); j++) {
        const vafm_param_info *f = vafm_params_field_at(j);
        if (f->kind != VAFM_PARAM_CHOICE)
            continue;
        char list[256], got[64];
        snprintf(list, sizeof list, "%s", f->choices);
        for (char *tok = strtok(list, "|"); tok; tok = strtok(NULL, "|")) {
            ENSURE_MSG(vafm_params_set(&p, f->name, tok, NULL) == 0, "%s = %s", f->name, tok);
            vafm_params_get(&p, f->name, got, sizeof got);
            ENSURE_MSG(!strcmp(got, tok), "%s: set %s, got %s", f->name, tok, got);
        }
    }
    /* boolean spellings; seeds at the ends of their range */
    const char *yes[] = {"1", "true", "TRUE", "yes", "on"}, *no[] = {"0", "false", "No", "off"};
    char got[64];
    for (size_t i = 0; i < 5; i++) {
        ENSURE(vafm_params_set(&p, "free_exact", yes[i], NULL) == 0 && p.free_exact == 1);
    }
    for (size_t i = 0; i < 4; i++) {
        ENSURE(vafm_params_set(&p, "free_exact", no[i], NULL) == 0 && p.free_exact == 0);
    }
    ENSURE(vafm_params_set(&p, "seed", "18446744073709551615", NULL) == 0 && p.seed == UINT64_MAX);
    vafm_params_get(&p, "seed", got, sizeof got);
    ENSURE(!strcmp(got, "18446744073709551615"));
    ENSURE(vafm_params_set(&p, "seed", "0", NULL) == 0 && p.seed == 0);
    ENSURE(vafm_params_set(&p, "k_N_per_m", "6.3e-3", NULL) == 0 && p.k_N_per_m == 6.3e-3);
}

/* Find "name": value in a flat JSON object and copy the value text (quotes stripped). */
static int t_json_value(const char *json, const char *name, char *out, size_t len)
{
    char key[96];
    snprintf(key, sizeof key, "\"%s\":", name);
    const char *p = strstr(json, key);
    if (!p)
        return -1;
    p += strlen(key);
    while (*p == ' ')
        p++;
    int quoted = *p == '"';
    if (quoted)
        p++;
    size_t n = 0;
    while (*p && n + 1 < len) {
        if (quoted ? *p == '"' : (*p == ',' || *p == '}' || *p == ' '))
            break;
        out[n++] = *p++;
    }
    out[n] = '\0';
    return 0;
}

static void test_json(void)
{
    for (int i = 0; i < vafm_preset_count(); i++) {
        vafm_params p;
        vafm_preset_apply(&p, vafm_preset_name(i), NULL);
        char json[8192];
        int n = vafm_params_to_json(&p, json, sizeof json);
        ENSURE(n > 0 && (size_t)n == strlen(json));
        ENSURE(json[0] == '{' && json[n - 1] == '}');
        for (int j = 0; j < vafm_params_field_count(); j++) {
            const vafm_param_info *f = vafm_params_field_at(j);
            char a[128], b[128];
            vafm_params_get(&p, f->name, a, sizeof a);
            ENSURE_MSG(t_json_value(json, f->name, b, sizeof b) == 0, "%s missing from JSON", f->name);
            ENSURE_MSG(!strcmp(a, b), "%s: JSON '%s' vs get '%s'", f->name, b, a);
        }
        /* too small a buffer: an error, never a truncated object */
        char small[32];
        ENSURE(vafm_params_to_json(&p, small, sizeof small) == VAFM_EINVAL);
        ENSURE(vafm_params_to_json(&p, json, (size_t)n) == VAFM_EINVAL); /* no room for the NUL */
        ENSURE(vafm_params_to_json(&p, json, (size_t)n + 1) == n);
    }
}

/* One bad text value: the error code, the field named in err and (REAL) the range in the message. */
static void t_bad(const vafm_param_info *f, const char *value, int want_range)
{
    vafm_params p, before;
    vafm_params_default(&p);
    before = p;
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = vafm_params_set(&p, f->name, value, &err);
    ENSURE_MSG(r == VAFM_EINVAL, "%s = '%s' accepted (%d)", f->name, value, r);
    ENSURE_MSG(err.code == VAFM_EINVAL, "%s = '%s': err.code %d", f->name, value, err.code);
    ENSURE_MSG(!strcmp(err.field, f->name), "%s = '%s': err.field '%s'", f->name, value, err.field);
    ENSURE_MSG(strstr(err.message, f->name) != NULL, "%s: message '%s'", f->name, err.message);
    ENSURE_MSG(memcmp(&p, &before, sizeof p) == 0, "%s = '%s': refused value changed the scene", f->name, value);
    if (want_range) {
        char range[96];
        t_range_text(f, range, sizeof range);
        ENSURE_MSG(strstr(err.message, range) != NULL, "%s = '%s': message '%s' lacks range %s", f->name, value,
                   err.message, range);
    }
}

static void test_bad_text_values(void)
{
    for (int j = 0; j < vafm_params_field_count(); j++) {
        const vafm_param_info *f = vafm_params_field_at(j);
        char buf[64];
        switch (f->kind) {
        case VAFM_PARAM_REAL:
            /* the nearest doubles outside the closed range, written exactly */
            snprintf(buf, sizeof buf, "%.17g", nextafter(f->min, -INFINITY));
            t_bad(f, buf, 1);
            snprintf(buf, sizeof buf, "%.17g", nextafter(f->max, INFINITY));
            t_bad(f, buf, 1);
            t_bad(f, "nan", 1);
            t_bad(f, "inf", 1);
            t_bad(f, "-inf", 1);
            t_bad(f, "abc", 1);
            t_bad(f, "1.5x", 1);
            t_bad(f, "", 1);
            /* the ends themselves are allowed */
            {
                vafm_params p;
                vafm_params_default(&p);
                snprintf(buf, sizeof buf, "%.17g", f->min);
                ENSURE_MSG(vafm_params_set(&p, f->name, buf, NULL) == 0, "%s = min refused", f->name);
                snprintf(buf, sizeof buf, "%.17g", f->max);
                ENSURE_MSG(vafm_params_set(&p, f->name, buf, NULL) == 0, "%s = max refused", f->name);
            }
            break;
        case VAFM_PARAM_CHOICE:
            t_bad(f, "bogus", 0);
            t_bad(f, "", 0);
            t_bad(f, "GJF ", 0);
            break;
        case VAFM_PARAM_BOOL:
            t_bad(f, "maybe", 0);
            t_bad(f, "2", 0);
            t_bad(f, "", 0);
            t_bad(f, "-1", 0);
            break;
        case VAFM_PARAM_INT:
            t_bad(f, "8.5", 0); /* not a whole number */
            snprintf(buf, sizeof buf, "%.0f", f->max + 1); /* above the range */
            t_bad(f, buf, 0);
            t_bad(f, "-1", 0);
            t_bad(f, "", 0);
            t_bad(f, "12x", 0);
            break;
        case VAFM_PARAM_SEED:
            t_bad(f, "-1", 0);
            t_bad(f, " -1", 0); /* strtoull would wrap a negated value to 2^64 - 1 */
            t_bad(f, "18446744073709551616", 0); /* 2^64: overflow */
            t_bad(f, "99999999999999999999999", 0);
            t_bad(f, "12x", 0);
            t_bad(f, "1.5", 0);
            t_bad(f, "", 0);
            break;
        default: break;
        }
    }
    /* unknown field: VAFM_ENOTFOUND from set (naming it) and get */
    vafm_params p;
    vafm_params_default(&p);
    vafm_error err;
    memset(&err, 0, sizeof err);
    char buf[64];
    ENSURE(vafm_params_set(&p, "no_such_field", "1", &err) == VAFM_ENOTFOUND);
    ENSURE(err.code == VAFM_ENOTFOUND && !strcmp(err.field, "no_such_field"));
    ENSURE(strstr(err.message, "no_such_field") != NULL);
    ENSURE(vafm_params_get(&p, "no_such_field", buf, sizeof buf) == VAFM_ENOTFOUND);
    ENSURE(vafm_params_set(&p, NULL, "1", &err) == VAFM_ENOTFOUND);
    ENSURE(vafm_params_set(&p, "k_N_per_m", "1e-3", NULL) == 0); /* err may be NULL */
    ENSURE(vafm_params_set(&p, "k_N_per_m", "-1", NULL) == VAFM_EINVAL);
}

/* The REAL members of vafm_params by name: the test's own map, checked against the field table so
 * that a field added to one and not the other fails here. */
static const struct {
    const char *name;
    size_t off;
} t_real_members[] = {
#define M(x) {#x, offsetof(vafm_params, x)}
    M(E_star_Pa), M(R_m), M(gamma_J_per_m2), M(k_N_per_m), M(m_kg), M(eta_per_s), M(f0_Hz), M(Q), M(eta_cont_per_s), M(T_K),
    M(v_approach_m_per_s), M(v_retract_m_per_s), M(start_height_m), M(setpoint_N), M(trigger_height_m),
    M(z_range_m), M(dwell_s), M(retract_margin_m), M(retract_max_m), M(sample_rate_Hz), M(tune_duration_s),
    M(dt_s), M(omega_dt), M(omega_dt_far), M(near_barrier_kT), M(sensitivity_m_per_V), M(noise_V_rms),
    M(adc_range_V), M(baseline_offset_V), M(ramp_size_m), M(ramp_rate_Hz), M(extend_time_s), M(retract_time_s),
    M(setpoint_V), M(dwell_feedback_s), M(tune_rate_Hz),
    M(surface_height_m), M(drift_V_per_s), M(drift_walk_V_per_sqrt_s), M(virtual_deflection_V_per_m),
    M(interference_V), M(interference_period_m), M(flicker_corner_Hz), M(mains_V), M(mains_Hz),
    M(contact_point_sd_m), M(sample_drift_m_per_s), M(piezo_hysteresis), M(piezo_hysteresis_length_m), M(piezo_creep),
    M(piezo_creep_t0_s), M(zsensor_noise_m), M(zsensor_bandwidth_Hz),
#undef M
};
#define T_NREAL (sizeof t_real_members / sizeof t_real_members[0])

static double *t_member(vafm_params *p, const char *name)
{
    for (size_t i = 0; i < T_NREAL; i++)
        if (!strcmp(t_real_members[i].name, name))
            return (double *)((char *)p + t_real_members[i].off);
    return NULL;
}

/* vafm_params_validate on a valid scene with one REAL member out of range (below, above, NaN, ±inf):
 * VAFM_EINVAL, err.field = that field, the range in the message. */
static void t_validate_bad(const vafm_param_info *f, double v)
{
    vafm_params p;
    vafm_preset_apply(&p, "paper-fig4", NULL);
    double *slot = t_member(&p, f->name);
    ENSURE_MSG(slot != NULL, "%s: not in the test's member map", f->name);
    if (!slot)
        return;
    *slot = v;
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = vafm_params_validate(&p, &err);
    ENSURE_MSG(r == VAFM_EINVAL, "validate %s = %g: %d", f->name, v, r);
    ENSURE_MSG(err.code == VAFM_EINVAL, "validate %s = %g: err.code %d", f->name, v, err.code);
    ENSURE_MSG(!strcmp(err.field, f->name), "validate %s = %g: field '%s'", f->name, v, err.field);
    char range[96];
    t_range_text(f, range, sizeof range);
    ENSURE_MSG(strstr(err.message, range) != NULL, "validate %s: message '%s' lacks %s", f->name, err.message,
               range);
}

static void test_validate_fields(void)
{
    int n_real = 0;
    for (int j = 0; j < vafm_params_field_count(); j++)
        n_real += vafm_params_field_at(j)->kind == VAFM_PARAM_REAL;
    ENSURE_MSG(n_real == (int)T_NREAL, "field table has %d REAL fields, the test knows %zu", n_real, T_NREAL);
    /* the member map really addresses the named fields: set through text, read the member */
    for (size_t i = 0; i < T_NREAL; i++) {
        const vafm_param_info *f = vafm_params_field_find(t_real_members[i].name);
        ENSURE_MSG(f && f->kind == VAFM_PARAM_REAL, "%s is not a REAL field", t_real_members[i].name);
        if (!f)
            continue;
        vafm_params p;
        vafm_params_default(&p);
        char buf[64];
        snprintf(buf, sizeof buf, "%.17g", f->max);
        ENSURE(vafm_params_set(&p, f->name, buf, NULL) == 0);
        ENSURE_MSG(*t_member(&p, f->name) == f->max, "%s: member map wrong", f->name);
    }
    for (int j = 0; j < vafm_params_field_count(); j++) {
        const vafm_param_info *f = vafm_params_field_at(j);
        if (f->kind != VAFM_PARAM_REAL)
            continue;
        t_validate_bad(f, nextafter(f->min, -INFINITY));
        t_validate_bad(f, nextafter(f->max, INFINITY));
        t_validate_bad(f, NAN);
        t_validate_bad(f, INFINITY);
        t_validate_bad(f, -INFINITY);
    }
    /* CHOICE / BOOL members with impossible values */
    vafm_params p;
    vafm_error err;
    struct { const char *field; int *member; int bad; } ints[] = {
        {"trigger", &p.trigger, 2}, {"noise", &p.noise, -1}, {"antialias", &p.antialias, 7},
        {"free_exact", &p.free_exact, 2},
    };
    for (size_t i = 0; i < sizeof ints / sizeof ints[0]; i++) {
        vafm_params_default(&p);
        *ints[i].member = ints[i].bad;
        memset(&err, 0, sizeof err);
        ENSURE_MSG(vafm_params_validate(&p, &err) == VAFM_EINVAL, "%s = %d accepted", ints[i].field, ints[i].bad);
        ENSURE_MSG(!strcmp(err.field, ints[i].field), "%s: field '%s'", ints[i].field, err.field);
    }
    vafm_params_default(&p);
    p.contact = NULL;
    memset(&err, 0, sizeof err);
    ENSURE(vafm_params_validate(&p, &err) == VAFM_EINVAL && !strcmp(err.field, "contact"));
    vafm_params_default(&p);
    p.integrator = NULL;
    memset(&err, 0, sizeof err);
    ENSURE(vafm_params_validate(&p, &err) == VAFM_EINVAL && !strcmp(err.field, "integrator"));
    /* combinations: hertz with adhesion; a height trigger above the start */
    vafm_params_default(&p);
    p.contact = vafm_contact_hertz;
    memset(&err, 0, sizeof err);
    ENSURE(vafm_params_validate(&p, &err) == VAFM_EINVAL && !strcmp(err.field, "gamma_J_per_m2"));
    p.gamma_J_per_m2 = 0.0;
    ENSURE(vafm_params_validate(&p, &err) == 0);
    vafm_params_default(&p);
    p.trigger = VAFM_TRIGGER_HEIGHT;
    p.trigger_height_m = p.start_height_m;
    memset(&err, 0, sizeof err);
    ENSURE(vafm_params_validate(&p, &err) == VAFM_EINVAL && !strcmp(err.field, "trigger_height_m"));
}

/* reduce ∘ from_reduced is the identity on the reduced model, and from_reduced ∘ reduce on the SI
 * scene (E*, R and m are kept): rounding only, a few ulps per product/quotient → 1e-14. */
static void test_units_roundtrip(void)
{
    const vafm_reduced cases[] = {
        {.m = 5e-5, .eta_cont = 0.0, .k = 2e-5, .kT = 5e-8, .gamma = 1.2e-4, .v_approach = 1e-4, .v_retract = 1e-4},
        {.m = 0.01, .eta_cont = 3.0, .k = 0.1, .kT = 0.01, .gamma = 0.229, .v_approach = 1e-3, .v_retract = 0.5},
        {.m = 1.0, .eta_cont = 0.5, .k = 1e3, .kT = 0.0, .gamma = 0.0, .v_approach = 1e-7, .v_retract = 2e-7},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        const vafm_reduced *r = &cases[i];
        for (int pre = 0; pre < vafm_preset_count(); pre++) {
            vafm_params p;
            vafm_preset_apply(&p, vafm_preset_name(pre), NULL);
            vafm_units_from_reduced(&p, r);
            vafm_reduced b;
            vafm_units_reduce(&p, &b);
            ENSURE_REL(b.m, r->m, 1e-14);
            ENSURE_REL(b.k, r->k, 1e-14);
            ENSURE_REL(b.v_approach, r->v_approach, 1e-14);
            ENSURE_REL(b.v_retract, r->v_retract, 1e-14);
            ENSURE_ABS(b.kT, r->kT, 1e-14 * r->kT);
            ENSURE_ABS(b.gamma, r->gamma, 1e-14 * r->gamma);
            ENSURE_ABS(b.eta_cont, r->eta_cont, 1e-14 * r->eta_cont);
            /* and back: the SI scene is a fixed point */
            vafm_params q = p;
            vafm_units_from_reduced(&q, &b);
            ENSURE_REL(q.eta_per_s, p.eta_per_s, 1e-14);
            ENSURE_REL(q.k_N_per_m, p.k_N_per_m, 1e-14);
            ENSURE_REL(q.v_retract_m_per_s, p.v_retract_m_per_s, 1e-14);
            ENSURE_ABS(q.T_K, p.T_K, 1e-14 * p.T_K);
            ENSURE_ABS(q.gamma_J_per_m2, p.gamma_J_per_m2, 1e-14 * p.gamma_J_per_m2);
        }
    }
    /* the scale factors are the notes' units: length R, time 1/η, force E*R², energy E*R³ */
    vafm_params p;
    vafm_preset_apply(&p, "paper-fig4", NULL);
    vafm_scale s = vafm_units_scale(&p);
    ENSURE_REL(s.length_m, p.R_m, 1e-15);
    ENSURE_REL(s.time_s, 1.0 / p.eta_per_s, 1e-15);
    ENSURE_REL(s.force_N, p.E_star_Pa * p.R_m * p.R_m, 1e-15);
    ENSURE_REL(s.energy_J, p.E_star_Pa * p.R_m * p.R_m * p.R_m, 1e-15);
    ENSURE_REL(s.speed_m_per_s, p.R_m * p.eta_per_s, 1e-15);
    ENSURE_REL(s.stiffness_N_per_m, p.E_star_Pa * p.R_m, 1e-15);
}

/* The paper's Fig. 1/2 scene (physics notes, "Units"): reduced m̃ = 5e-5, ṽ = 1e-4, k̃ = 2e-5,
 * k_BT̃ = 5e-8, γ̃ = 1.2e-4 with E* = 20 GPa, R = 15.7 nm, m = 1e-12 kg; k ≈ 6.3 mN/m and v ≈ 196.3 nm/s
 * as the notes round them (0.5%). */
static void test_paper_fig1(void)
{
    vafm_params p;
    ENSURE(vafm_preset_apply(&p, "paper-fig1", NULL) == 0);
    ENSURE_REL(p.E_star_Pa, 20e9, 1e-15);
    ENSURE_REL(p.R_m, 15.7e-9, 1e-15);
    ENSURE_REL(p.m_kg, 1e-12, 1e-15);
    ENSURE_REL(p.k_N_per_m, 6.3e-3, 5e-3);
    ENSURE_REL(p.v_approach_m_per_s, 196.3e-9, 5e-3);
    ENSURE_REL(p.v_retract_m_per_s, 196.3e-9, 5e-3);
    ENSURE(p.contact == vafm_contact_jkr);
    ENSURE(p.integrator == vafm_integrator_gjf);
    vafm_reduced r;
    vafm_units_reduce(&p, &r);
    ENSURE_REL(r.m, 5e-5, 1e-14);
    ENSURE_REL(r.v_approach, 1e-4, 1e-14);
    ENSURE_REL(r.k, 2e-5, 1e-14);
    ENSURE_REL(r.kT, 5e-8, 1e-14);
    ENSURE_REL(r.gamma, 1.2e-4, 1e-14);
    /* the SI values that follow (the notes quote γ = 0.036 J/m² and T = 288.4 K, rounded from a
     * slightly different k; the exact reduced values give these) */
    const double ER = 20e9 * 15.7e-9;
    ENSURE_REL(p.gamma_J_per_m2, 1.2e-4 * ER, 1e-14);
    ENSURE_REL(p.T_K, 5e-8 * ER * 15.7e-9 * 15.7e-9 / VAFM_KB_J_PER_K, 1e-14);
    ENSURE_REL(p.eta_per_s, sqrt(5e-5 * ER / 1e-12), 1e-14);

    /* paper-fig4: γ̃ = 0.229, k̃ = 0.1, m̃ = 0.01, k_BT̃ = 0.01, ṽ = 1e-3 (E* = 1 GPa, R = 16 nm) */
    ENSURE(vafm_preset_apply(&p, "paper-fig4", NULL) == 0);
    vafm_units_reduce(&p, &r);
    ENSURE_REL(r.gamma, 0.229, 1e-14);
    ENSURE_REL(r.k, 0.1, 1e-14);
    ENSURE_REL(r.m, 0.01, 1e-14);
    ENSURE_REL(r.kT, 0.01, 1e-14);
    ENSURE_REL(r.v_retract, 1e-3, 1e-14);
    ENSURE(vafm_preset_apply(&p, "paper-fig4-bd", NULL) == 0);
    vafm_units_reduce(&p, &r);
    ENSURE(p.integrator == vafm_integrator_brownian);
    ENSURE_REL(r.m, 1.0, 1e-14); /* ζ = mη = 1 reduced */
}

static void test_strerror(void)
{
    const int codes[] = {VAFM_OK, VAFM_EINVAL, VAFM_ENOMEM, VAFM_EUNSTABLE, VAFM_EIO, VAFM_EFORMAT,
                         VAFM_ENOTSUP, VAFM_EABORT, VAFM_ESTATE, VAFM_ENOTFOUND, VAFM_EACCES};
    const int n = (int)(sizeof codes / sizeof codes[0]);
    const char *unknown = vafm_strerror(12345);
    ENSURE(unknown != NULL && unknown[0]);
    ENSURE(vafm_strerror(-11) != NULL && !strcmp(vafm_strerror(-11), unknown)); /* the first code past the last */
    for (int i = 0; i < n; i++) {
        const char *s = vafm_strerror(codes[i]);
        ENSURE(s != NULL && s[0]);
        ENSURE_MSG(strcmp(s, unknown) != 0, "code %d has no description", codes[i]);
        for (int j = 0; j < i; j++)
            ENSURE_MSG(strcmp(s, vafm_strerror(codes[j])) != 0, "codes %d and %d share '%s'", codes[i], codes[j], s);
    }
    ENSURE(vafm_version() && vafm_version()[0]);
    /* the release's version (meson.build), not the API's: 0.6.1 called itself 0.6.0 */
    ENSURE_MSG(strcmp(vafm_version(), VAFM_PROJECT_VERSION) == 0, "vafm_version() '%s', meson.build '%s'",
               vafm_version(), VAFM_PROJECT_VERSION);
    ENSURE(vafm_version_api() == ((VAFM_API_VERSION_MAJOR << 16) | (VAFM_API_VERSION_MINOR << 8) | VAFM_API_VERSION_PATCH));
}

/* The cost estimate (issue #18, finding 5) against real curves: the typical duration within 30% of a
 * curve's, the longest bound above it; the limits refuse what they say, naming the field. */
static void test_cost_estimate(void)
{
    static const char *presets[] = { "paper-fig4", "paper-fig4-bd" };
    for (size_t k = 0; k < sizeof presets / sizeof presets[0]; k++) {
        vafm_params p;
        vafm_preset_apply(&p, presets[k], NULL);
        p.v_approach_m_per_s = p.v_retract_m_per_s = 6.4e-5; /* fast: a few ms a curve */
        vafm_sim_estimate est;
        vafm_error e;
        ENSURE(vafm_sim_estimate_cost(&p, &est, &e) == 0);
        vafm_sim *sim = NULL;
        vafm_curve_result r;
        ENSURE(vafm_sim_new(&sim, &p, &e) == 0);
        ENSURE(sim && vafm_sim_curve(sim, 0, NULL, NULL, &r) == 0);
        vafm_sim_destroy(&sim);
        ENSURE_MSG(fabs(est.duration_s / r.duration_s - 1.0) < 0.3, "%s: estimate %g s, curve %g s", presets[k],
                   est.duration_s, r.duration_s);
        ENSURE_MSG(est.duration_max_s >= r.duration_s, "%s: bound %g s < curve %g s", presets[k], est.duration_max_s,
                   r.duration_s);
        ENSURE(fabs(est.samples - est.duration_s * p.sample_rate_Hz) <= 1e-6 * est.samples);
        ENSURE(est.steps >= (double)r.steps * 0.5); /* the plain-step count bounds the shortcut run's */
    }
    vafm_params p;
    vafm_preset_apply(&p, "paper-fig4", NULL);
    vafm_error e;
    memset(&e, 0, sizeof e);
    p.sample_rate_Hz = 1e10;
    ENSURE(vafm_params_validate(&p, &e) == VAFM_EINVAL && !strcmp(e.field, "sample_rate_Hz"));
    vafm_preset_apply(&p, "paper-fig4", NULL);
    p.dwell_s = 1e4;
    ENSURE(vafm_params_validate(&p, &e) == VAFM_EINVAL && !strcmp(e.field, "dwell_s"));
    vafm_preset_apply(&p, "paper-fig4", NULL);
    p.v_retract_m_per_s = 1e-12;
    ENSURE(vafm_params_validate(&p, &e) == VAFM_EINVAL && !strcmp(e.field, "v_retract_m_per_s"));
    vafm_preset_apply(&p, "paper-fig1", NULL);
    p.sample_rate_Hz = 8e6; /* the highest rate the daemon is benchmarked at stays allowed */
    ENSURE(vafm_params_validate(&p, &e) == 0);
}

/* An instrument's cantilever words (issue #16): f0 and Q give the mass k/(2π f0)² and the friction 2π f0/Q;
 * the reduced scene equals the one given by m and η directly; 0 leaves m_kg and eta_per_s in charge. */
static void test_f0_Q(void)
{
    vafm_params a, b;
    vafm_preset_apply(&a, "paper-fig1", NULL);
    b = a;
    double w0 = sqrt(a.k_N_per_m / a.m_kg), f0 = w0 / (2.0 * M_PI), Q = w0 / a.eta_per_s;
    ENSURE(vafm_params_set(&b, "f0_Hz", "0", NULL) == 0 && vafm_params_mass_kg(&b) == a.m_kg);
    char t[64];
    snprintf(t, sizeof t, "%.17g", f0);
    ENSURE(vafm_params_set(&b, "f0_Hz", t, NULL) == 0);
    snprintf(t, sizeof t, "%.17g", Q);
    ENSURE(vafm_params_set(&b, "Q", t, NULL) == 0);
    b.m_kg = 2e-12; /* unused now */
    b.eta_per_s = 7.0;
    ENSURE_REL(vafm_params_mass_kg(&b), a.m_kg, 1e-14);
    ENSURE_REL(vafm_params_eta_per_s(&b), a.eta_per_s, 1e-14);
    vafm_reduced ra, rb;
    vafm_units_reduce(&a, &ra);
    vafm_units_reduce(&b, &rb);
    ENSURE_REL(rb.m, ra.m, 1e-13);
    ENSURE_REL(rb.k, ra.k, 1e-15);
    ENSURE_REL(rb.v_retract, ra.v_retract, 1e-14);
    ENSURE(vafm_params_validate(&b, NULL) == 0);
    /* a resonance that gives a mass outside m_kg's range is refused naming f0_Hz */
    vafm_error e;
    memset(&e, 0, sizeof e);
    b.f0_Hz = 1e9;
    b.k_N_per_m = 1e-6;
    ENSURE(vafm_params_validate(&b, &e) == VAFM_EINVAL && !strcmp(e.field, "f0_Hz"));
}

/* Values print as the shortest text that reads back exactly (issue #16): 0.1, not 0.10000000000000001. */
static void test_shortest_text(void)
{
    vafm_params p;
    vafm_params_default(&p);
    char buf[64];
    p.k_N_per_m = 0.1;
    ENSURE(vafm_params_get(&p, "k_N_per_m", buf, sizeof buf) == 0 && !strcmp(buf, "0.1"));
    p.k_N_per_m = 0.1 + 0.2; /* 0.30000000000000004: every digit needed */
    ENSURE(vafm_params_get(&p, "k_N_per_m", buf, sizeof buf) == 0 && strtod(buf, NULL) == p.k_N_per_m &&
           !strcmp(buf, "0.30000000000000004"));
    for (int i = 0; i < vafm_params_field_count(); i++) {
        const vafm_param_info *f = vafm_params_field_at(i);
        if (f->kind != VAFM_PARAM_REAL)
            continue;
        vafm_preset_apply(&p, "paper-fig4", NULL);
        ENSURE(vafm_params_get(&p, f->name, buf, sizeof buf) == 0);
        vafm_params q = p;
        ENSURE_MSG(vafm_params_set(&q, f->name, buf, NULL) == 0 && !memcmp(&p, &q, sizeof p), "%s = %s", f->name, buf);
    }
}

/* Values typed with their units: each accepted spelling gives exactly the double of the same decimal written
 * in SI ("60nm/V" is 60e-9, not 60 * 1e-9, which rounds twice), each wrong unit is refused with the field
 * named. */
static void test_units_parse(void)
{
    static const struct {
        const char *unit, *text;
        double want;
    } ok[] = {
        { "N", "1nN", 1e-9 },       { "N", "1e-9", 1e-9 },          { "N", "2.5 pN", 2.5e-12 },
        { "m", "1um", 1e-6 },       { "m", "1\xc2\xb5m", 1e-6 },   { "m", "1m", 1.0 },
        { "m", "300mm", 300e-3 },   { "m/s", "2um/s", 2e-6 },       { "m/s", "-1e3nm/s", -1e-6 },
        { "Hz", "70kHz", 70e3 },    { "Hz", "1.5MHz", 1.5e6 },      { "K", "25C", 25.0 + 273.15 },
        { "K", "300K", 300.0 },     { "K", "-10degC", -10.0 + 273.15 }, { "J/m^2", "50mJ/m^2", 50e-3 },
        { "J/m^2", "50mJ/m2", 50e-3 }, { "Pa", "1MPa", 1e6 },       { "Pa", "5kPa", 5e3 },
        { "s", "10ms", 10e-3 },     { "m/V", "60nm/V", 60e-9 },     { "", "30", 30.0 },
        { "N", "1.1nN", 1.1e-9 },   { "m/V", "1.7e2nm/V", 1.7e-7 }, { "Hz", "0.3kHz", 0.3e3 },
        { "m/s", "2\xce\xbcm/s", 2e-6 } /* Greek mu U+03BC, as keyboards type it (0.6.2 took only µ U+00B5) */,
    };
    for (size_t i = 0; i < sizeof ok / sizeof ok[0]; i++) {
        double v = NAN;
        vafm_error err;
        memset(&err, 0, sizeof err);
        int r = vafm_units_parse("f", ok[i].text, ok[i].unit, &v, &err);
        ENSURE_MSG(r == 0 && v == ok[i].want, "'%s' in %s: %d, %.17g (want %.17g) %s", ok[i].text, ok[i].unit, r, v,
                   ok[i].want, err.message);
    }
    static const struct {
        const char *unit, *text;
    } bad[] = {
        { "N", "1nm" },  { "N", "1 nN " }, { "N", "1  nN" }, { "N", "1cN" },   { "m", "1um/s" }, { "m/s", "2um" },
        { "Hz", "70k" }, { "K", "25F" },   { "Pa", "1MPA" }, { "", "30m" },    { "N", "nan" },   { "N", "inf" },
        { "N", "0x10" }, { "N", "" },      { "N", "nN" },    { "K", "25kC" },  { "m", "1e" },    { "N", "1e400" },
        /* underflow: a nonzero literal that reads as 0 or a subnormal (issue #29 item 10) */
        { "N", "1e-400" }, { "N", "-1e-400" }, { "N", "4e-320" }, { "N", "1e-300fN" }, { "N", "0.00000001e-301" },
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        double v = 7.0;
        vafm_error err;
        memset(&err, 0, sizeof err);
        int r = vafm_units_parse("setpoint_N", bad[i].text, bad[i].unit, &v, &err);
        ENSURE_MSG(r == VAFM_EINVAL && v == 7.0 && !strcmp(err.field, "setpoint_N") &&
                       strstr(err.message, "setpoint_N") != NULL,
                   "'%s' in %s accepted or badly refused: %d '%s'", bad[i].text, bad[i].unit, r, err.message);
    }
    /* through the field table: the field's own unit decides */
    vafm_params p;
    vafm_params_default(&p);
    ENSURE(vafm_params_set(&p, "setpoint_N", "2nN", NULL) == 0 && p.setpoint_N == 2e-9);
    ENSURE(vafm_params_set(&p, "T_K", "25C", NULL) == 0 && p.T_K == 298.15);
    vafm_error err;
    memset(&err, 0, sizeof err);
    ENSURE(vafm_params_set(&p, "setpoint_N", "2nm", &err) == VAFM_EINVAL && !strcmp(err.field, "setpoint_N") &&
           strstr(err.message, "[0, 1] N") != NULL);
    /* an underflow names the field and the range; zero itself and the smallest normal double are values */
    memset(&err, 0, sizeof err);
    ENSURE(vafm_params_set(&p, "setpoint_N", "1e-400", &err) == VAFM_EINVAL && p.setpoint_N == 2e-9 &&
           !strcmp(err.field, "setpoint_N") && strstr(err.message, "underflows") && strstr(err.message, "[0, 1] N"));
    memset(&err, 0, sizeof err);
    ENSURE(vafm_params_set(&p, "T_K", "1e-400", &err) == VAFM_EINVAL && p.T_K == 298.15 && !strcmp(err.field, "T_K"));
    ENSURE(vafm_params_set(&p, "setpoint_N", "0e-400", NULL) == 0 && p.setpoint_N == 0.0);
    ENSURE(vafm_params_set(&p, "setpoint_N", "0.000nN", NULL) == 0 && p.setpoint_N == 0.0);
    ENSURE(vafm_params_set(&p, "setpoint_N", "2.2250738585072014e-308", NULL) == 0 && p.setpoint_N == DBL_MIN);
}

/* The instrument's ramp settings derive the fields underneath; a field changed afterwards is caught. */
static void test_resolve(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL);
    vafm_error err;
    memset(&err, 0, sizeof err);
    p.ramp_size_m = 0; /* an adaptive ramp */
    p.ramp_rate_Hz = 1.0;
    ENSURE(vafm_params_resolve(&p, &err) == VAFM_EINVAL && !strcmp(err.field, "ramp_rate_Hz")); /* no ramp size */
    p.ramp_size_m = 500e-9;
    ENSURE(vafm_params_resolve(&p, &err) == 0);
    ENSURE(p.v_approach_m_per_s == 2.0 * 500e-9 * 1.0 && p.v_retract_m_per_s == p.v_approach_m_per_s);
    ENSURE(vafm_params_validate(&p, NULL) == 0);
    p.v_approach_m_per_s *= 2; /* a campaign axis over v while the ramp rate is set */
    memset(&err, 0, sizeof err);
    ENSURE(vafm_params_validate(&p, &err) == VAFM_EINVAL && !strcmp(err.field, "v_approach_m_per_s") &&
           strstr(err.message, "ramp_rate_Hz") != NULL);
    p.extend_time_s = 0.25;
    ENSURE(vafm_params_resolve(&p, &err) == VAFM_EINVAL && !strcmp(err.field, "ramp_rate_Hz")); /* both given */
    p.ramp_rate_Hz = 0;
    p.retract_time_s = 0.5;
    p.segment_samples = 1000;
    ENSURE(vafm_params_resolve(&p, &err) == 0);
    ENSURE(p.v_approach_m_per_s == 500e-9 / 0.25 && p.v_retract_m_per_s == 500e-9 / 0.5);
    ENSURE_MSG(fabs(p.sample_rate_Hz - 1000 / 0.25) < 1e-9, "segment_samples: %.17g Hz", p.sample_rate_Hz);
    ENSURE(vafm_params_validate(&p, NULL) == 0);
    /* setpoint in volts: absolute less the offset, relative not */
    p.setpoint_V = 0.5;
    p.baseline_offset_V = 0.1;
    ENSURE(vafm_params_resolve(&p, NULL) == 0);
    ENSURE(fabs(p.setpoint_N - p.k_N_per_m * p.sensitivity_m_per_V * 0.4) < 1e-24);
    p.setpoint_mode = VAFM_SETPOINT_RELATIVE;
    ENSURE(vafm_params_resolve(&p, NULL) == 0);
    ENSURE(fabs(p.setpoint_N - p.k_N_per_m * p.sensitivity_m_per_V * 0.5) < 1e-24);
    p.setpoint_mode = VAFM_SETPOINT_ABSOLUTE;
    p.baseline_offset_V = 0.6; /* the absolute setpoint below the signal's offset would fire at once */
    memset(&err, 0, sizeof err);
    ENSURE(vafm_params_resolve(&p, &err) == VAFM_EINVAL && !strcmp(err.field, "setpoint_V"));
    /* the constant-force loop must not act faster than twice per sample */
    vafm_preset_apply(&p, "contact-silica", NULL);
    p.dwell_feedback_s = 1.5 / p.sample_rate_Hz;
    ENSURE(vafm_params_validate(&p, &err) == VAFM_EINVAL && !strcmp(err.field, "dwell_feedback_s"));
}

/* A tune samples fast enough to show the resonance: the first 1-2-5 rate at or above 4 f0 when the curve's
 * rate is lower, the curve's rate when it is not, tune_rate_Hz when given. */
static void test_tune_rate(void)
{
    static const char *const presets[] = { "paper-fig1", "paper-fig4", "contact-silica", "cell-liquid",
                                           "colloid-pdms", "stiff-polymer" };
    for (size_t i = 0; i < sizeof presets / sizeof presets[0]; i++) {
        vafm_params p, q;
        vafm_preset_apply(&p, presets[i], NULL);
        double f0 = sqrt(p.k_N_per_m / vafm_params_mass_kg(&p)) / (2.0 * M_PI), r = vafm_params_tune_rate_Hz(&p);
        double mant = r / pow(10.0, floor(log10(r)));
        int is125 = fabs(mant - 1) < 1e-9 || fabs(mant - 2) < 1e-9 || fabs(mant - 5) < 1e-9;
        ENSURE_MSG(r >= 4.0 * f0 * (1 - 1e-12) && (r == p.sample_rate_Hz || (is125 && r < 10.0 * f0)),
                   "%s: f0 %.6g Hz, tune at %.6g Hz (curve %.6g Hz)", presets[i], f0, r, p.sample_rate_Hz);
        vafm_params_tune_scene(&p, &q);
        ENSURE(q.sample_rate_Hz == r && q.segment_samples == 0 && vafm_params_validate(&q, NULL) == 0);
        p.tune_rate_Hz = 1234.5;
        ENSURE(vafm_params_tune_rate_Hz(&p) == 1234.5);
    }
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL); /* f0 = 13 kHz: 52 kHz → 100 kHz */
    ENSURE(vafm_params_tune_rate_Hz(&p) == 100e3);
    p.sample_rate_Hz = 250e3; /* already above: kept */
    ENSURE(vafm_params_tune_rate_Hz(&p) == 250e3);
}

/* vafm_sim_new_tune: a tune is bounded by its own length at its own rate, not by the force curve's at that
 * rate (0.6.1's CLI and vafmd refused a 10 ms tune of a 1 nm/s scene: a 400 s curve at the tune's 100 kHz);
 * a too long tune is refused naming tune_duration_s and tune_rate_Hz; a tune-only simulation runs no curve. */
static void test_sim_new_tune(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL); /* tune at 100 kHz */
    p.v_approach_m_per_s = p.v_retract_m_per_s = 1e-9;
    p.tune_duration_s = 1e-3;
    vafm_error e;
    memset(&e, 0, sizeof e);
    vafm_sim *sim = NULL;
    ENSURE(vafm_params_validate(&p, &e) == 0); /* at the curve's 10 kHz the curve fits */
    vafm_params q;
    vafm_params_tune_scene(&p, &q);
    ENSURE(vafm_sim_new(&sim, &q, &e) == VAFM_EINVAL && !sim); /* at the tune's rate a curve would not */
    ENSURE_MSG(vafm_sim_new_tune(&sim, &p, &e) == 0 && sim, "%s", e.message);
    if (sim) {
        ENSURE(vafm_sim_params(sim)->sample_rate_Hz == 100e3);
        ENSURE(vafm_sim_tune(sim, 0, NULL, NULL) == 0);
        ENSURE(vafm_sim_curve_begin(sim, 0) == VAFM_EINVAL && vafm_sim_error(sim) &&
               strstr(vafm_sim_error(sim)->message, "vafm_sim_new_tune"));
        vafm_sim_destroy(&sim);
    }
    p.tune_rate_Hz = 5e7; /* 1 ms: 50000 samples; a curve at 1 nm/s there: ~2e10 */
    ENSURE_MSG(vafm_sim_new_tune(&sim, &p, &e) == 0 && sim, "%s", e.message);
    vafm_sim_destroy(&sim);
    p.tune_duration_s = 10; /* 5e8 samples */
    memset(&e, 0, sizeof e);
    ENSURE(vafm_sim_new_tune(&sim, &p, &e) == VAFM_EINVAL && !sim);
    ENSURE_MSG(!strcmp(e.field, "tune_duration_s") && strstr(e.message, "tune_rate_Hz") &&
               strstr(e.message, "VAFM_SIM_MAX_SAMPLES"), "%s: %s", e.field, e.message);
    ENSURE(vafm_sim_new_tune(&sim, NULL, &e) == VAFM_EINVAL && !sim);
}

int main(void)
{
    RUN_TEST(test_sim_new_tune);
    RUN_TEST(test_tune_rate);
    RUN_TEST(test_units_parse);
    RUN_TEST(test_resolve);
    RUN_TEST(test_shortest_text);
    RUN_TEST(test_f0_Q);
    RUN_TEST(test_cost_estimate);
    RUN_TEST(test_field_table);
    RUN_TEST(test_presets);
    RUN_TEST(test_set_get_roundtrip);
    RUN_TEST(test_json);
    RUN_TEST(test_bad_text_values);
    RUN_TEST(test_validate_fields);
    RUN_TEST(test_units_roundtrip);
    RUN_TEST(test_paper_fig1);
    RUN_TEST(test_strerror);
    return harness_done();
}
