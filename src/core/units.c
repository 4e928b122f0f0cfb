/* SPDX-License-Identifier: MIT */
/* The only place where SI meets reduced units (physics notes, "Units"). */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "vafm/params.h"
#include "vafm/units.h"
#include "core/internal.h"

/* The lever's mass and friction from its resonance (f0, Q) or as given: the first step of every unit
 * conversion, so they live here, where the reduction needs them (declared in params.h). units.c calls
 * nothing in params.c or numerics.c: params → numerics → units is a line, not a circle. */
double vafm_params_mass_kg(const vafm_params *p)
{
    if (p->f0_Hz > 0) {
        double w = 2.0 * M_PI * p->f0_Hz;
        return p->k_N_per_m / (w * w);
    }
    return p->m_kg;
}

double vafm_params_eta_per_s(const vafm_params *p)
{
    if (p->Q > 0) {
        double f0 = p->f0_Hz > 0 ? p->f0_Hz : sqrt(p->k_N_per_m / p->m_kg) / (2.0 * M_PI);
        return 2.0 * M_PI * f0 / p->Q;
    }
    return p->eta_per_s;
}

vafm_scale vafm_units_scale(const vafm_params *p)
{
    vafm_scale s;
    s.length_m = p->R_m;
    const double eta = vafm_params_eta_per_s(p); /* eta_per_s, or 2π f0 / Q */
    s.time_s = 1.0 / eta;
    s.force_N = p->E_star_Pa * p->R_m * p->R_m;
    s.energy_J = s.force_N * p->R_m;
    s.speed_m_per_s = p->R_m * eta;
    s.stiffness_N_per_m = p->E_star_Pa * p->R_m;
    return s;
}

void vafm_units_reduce(const vafm_params *p, vafm_reduced *r)
{
    vafm_scale s = vafm_units_scale(p);
    const double m = vafm_params_mass_kg(p), eta = vafm_params_eta_per_s(p);
    r->m = m * eta * eta / s.stiffness_N_per_m;
    r->eta_cont = p->eta_cont_per_s / eta;
    r->k = p->k_N_per_m / s.stiffness_N_per_m;
    r->kT = VAFM_KB_J_PER_K * p->T_K / s.energy_J;
    r->gamma = p->gamma_J_per_m2 / s.stiffness_N_per_m;
    r->v_approach = p->v_approach_m_per_s / s.speed_m_per_s;
    r->v_retract = p->v_retract_m_per_s / s.speed_m_per_s;
}

void vafm_units_from_reduced(vafm_params *p, const vafm_reduced *r)
{
    double ER = p->E_star_Pa * p->R_m;
    p->f0_Hz = p->Q = 0; /* the scene is then given by m_kg and eta_per_s */
    p->eta_per_s = sqrt(r->m * ER / p->m_kg);
    p->eta_cont_per_s = r->eta_cont * p->eta_per_s;
    p->k_N_per_m = r->k * ER;
    p->T_K = r->kT * ER * p->R_m * p->R_m / VAFM_KB_J_PER_K;
    p->gamma_J_per_m2 = r->gamma * ER;
    p->v_approach_m_per_s = r->v_approach * p->R_m * p->eta_per_s;
    p->v_retract_m_per_s = r->v_retract * p->R_m * p->eta_per_s;
}

/* ---- values typed with their units ------------------------------------------------------------- */

typedef struct s_prefix {
    const char *text;
    int exp10;
} s_prefix;

/* The prefixes people use on an instrument's controls; no c, d, da, h (a "cN" or "dm/s" is a typo more often
 * than a wish) and no E, P (no AFM quantity needs them). */
static const s_prefix s_prefixes[] = {
    { "f", -15 }, { "p", -12 }, { "n", -9 }, { "u", -6 }, { "\xc2\xb5", -6 } /* µ, micro sign U+00B5 */,
    { "\xce\xbc", -6 } /* μ, Greek mu U+03BC: what most keyboards and NFKC give */, { "m", -3 },
    { "k", 3 },   { "M", 6 },   { "G", 9 },  { "T", 12 },
};

/* The decimal number num (n characters) times 10^exp10, read as one decimal: "60" with -9 reads "60e-9", so
 * 60nm/V is exactly the double of 60e-9 (a multiplication by 1e-9 would round twice). */
static double s_scaled(const char *num, size_t n, int exp10)
{
    char buf[96];
    size_t e = 0;
    while (e < n && num[e] != 'e' && num[e] != 'E')
        e++;
    long ex = e < n ? strtol(num + e + 1, NULL, 10) : 0;
    if (ex > 100000 || ex < -100000)
        ex = ex > 0 ? 100000 : -100000;
    snprintf(buf, sizeof buf, "%.*se%ld", (int)e, num, ex + exp10);
    return strtod(buf, NULL);
}

/* suffix == unit, with the squared-metre spellings m^2, m2 and m² taken as one */
static int s_unit_eq(const char *suffix, const char *unit)
{
    if (!strcmp(suffix, unit))
        return 1;
    const char *sq = strstr(unit, "m^2");
    if (!sq)
        return 0;
    size_t head = (size_t)(sq - unit);
    if (strncmp(suffix, unit, head))
        return 0;
    const char *rest = suffix + head;
    return !strcmp(rest, "m2") || !strcmp(rest, "m\xc2\xb2") || !strcmp(rest, "m^2");
}

/* Length of the plain decimal number that starts text: [+-] digits [. digits] [e [+-] digits]; 0 if none.
 * Hexadecimal, inf and nan (which strtod reads) are not what anybody types on an instrument. */
static size_t s_number_length(const char *t)
{
    size_t i = 0, digits = 0;
    if (t[i] == '+' || t[i] == '-')
        i++;
    while (t[i] >= '0' && t[i] <= '9')
        i++, digits++;
    if (t[i] == '.') {
        i++;
        while (t[i] >= '0' && t[i] <= '9')
            i++, digits++;
    }
    if (!digits)
        return 0;
    if (t[i] == 'e' || t[i] == 'E') {
        size_t j = i + 1;
        if (t[j] == '+' || t[j] == '-')
            j++;
        if (t[j] >= '0' && t[j] <= '9') {
            while (t[j] >= '0' && t[j] <= '9')
                j++;
            i = j;
        }
    }
    return i;
}

/* The number of n characters has a nonzero digit before its exponent. */
static int s_nonzero_literal(const char *t, size_t n)
{
    for (size_t i = 0; i < n && t[i] != 'e' && t[i] != 'E'; i++)
        if (t[i] >= '1' && t[i] <= '9')
            return 1;
    return 0;
}

/* A nonzero literal that reads as 0 or a subnormal (|v| < DBL_MIN, 2.2e-308) underflowed: refused, as
 * "1e-400" (0.6.2 set such a value to 0 without a word). */
static int s_underflow(const char *field, const char *text, size_t n, double v, vafm_error *err)
{
    if (!(fabs(v) < DBL_MIN) || !s_nonzero_literal(text, n))
        return 0;
    vafm_err_set(err, VAFM_EINVAL, field, "%s: '%s' underflows: a nonzero value must be at least %.17g in magnitude "
                 "(it would read as %g)", field, text, DBL_MIN, v);
    return VAFM_EINVAL;
}

int vafm_units_parse(const char *field, const char *text, const char *unit, double *out, vafm_error *err)
{
    if (!field)
        field = "";
    if (!unit)
        unit = "";
    size_t n = text ? s_number_length(text) : 0;
    int ok = n > 0 && n < 64;
    double v = 0.0;
    const char *end = text ? text + n : NULL;
    if (ok) {
        char num[64];
        memcpy(num, text, n);
        num[n] = '\0';
        v = strtod(num, NULL);
        ok = isfinite(v);
    }
    if (ok && s_underflow(field, text, n, v, err))
        return VAFM_EINVAL;
    if (ok) {
        const char *sfx = end;
        if (*sfx == ' ')
            sfx++;
        if (*sfx == '\0' && sfx == end) {
            *out = v;
            return 0;
        }
        if (*sfx && unit[0] && s_unit_eq(sfx, unit)) {
            *out = v;
            return 0;
        }
        if (!strcmp(unit, "K") && *sfx && (!strcmp(sfx, "C") || !strcmp(sfx, "degC") || !strcmp(sfx, "\xc2\xb0" "C"))) {
            *out = v + 273.15;
            return 0;
        }
        for (size_t i = 0; unit[0] && *sfx && i < sizeof s_prefixes / sizeof s_prefixes[0]; i++) {
            size_t pn = strlen(s_prefixes[i].text);
            if (!strncmp(sfx, s_prefixes[i].text, pn) && s_unit_eq(sfx + pn, unit)) {
                double w = s_scaled(text, n, s_prefixes[i].exp10);
                if (!isfinite(w))
                    break;
                if (s_underflow(field, text, n, w, err))
                    return VAFM_EINVAL;
                *out = w;
                return 0;
            }
        }
    }
    if (unit[0])
        vafm_err_set(err, VAFM_EINVAL, field,
                     "%s: '%s' is not a value in %s (a number in %s, or with the unit and an SI prefix f p n u m k M "
                     "G T, e.g. '1n%s'%s)",
                     field, text ? text : "", unit, unit, unit, !strcmp(unit, "K") ? " or Celsius, '25C'" : "");
    else
        vafm_err_set(err, VAFM_EINVAL, field, "%s: '%s' is not a number (dimensionless)", field, text ? text : "");
    return VAFM_EINVAL;
}
