/* SPDX-License-Identifier: MIT */
/*
 * Named scenes: the paper's reduced scenes in SI, each a fill function, and instrument presets in an
 * instrument's words, each a row of values, in one table (vafm_preset_*); vafm_params_default() is the
 * first of them. Apart from params.c, which holds the field table and validation: a preset sets fields,
 * it checks none.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "vafm/integrator.h"
#include "vafm/params.h"
#include "vafm/units.h"
#include "core/internal.h"

typedef struct s_preset {
    const char *name;
    const char *description;
    void (*fill)(vafm_params *p);         /* the paper's scenes */
    const struct s_instrument_row *inst; /* or an instrument preset's row */
} s_preset;

static void s_common(vafm_params *p)
{
    memset(p, 0, sizeof *p);
    p->contact = vafm_contact_jkr;
    p->integrator = vafm_integrator_gjf;
    p->trigger = VAFM_TRIGGER_FORCE;
    p->noise = VAFM_NOISE_GAUSSIAN;
    p->antialias = VAFM_ANTIALIAS_MEAN;
    p->omega_dt = VAFM_OMEGA_DT_PAPER; /* chosen by evidence: docs/speed-and-accuracy.md, "The default step" */
    p->omega_dt_far = 0.0;
    /* far-zone escapes are then negligible: their probability is at most (ω/2π)·T·e^{−30} ≈ 1e-13·ωT,
     * 1e-7 for the paper-fig1 curve (ω ≈ 60 /η, T ≈ 1e5 /η) */
    p->near_barrier_kT = 30.0;
    p->free_exact = 1;
    p->contact_table = 1;
    p->well_exact = 1;
    p->seed = 1;
    p->sensitivity_m_per_V = 50e-9; /* a typical optical lever: 50 nm/V */
    p->adc_range_V = 20.0;          /* ±10 V, a typical controller input */
    p->interference_period_m = 335e-9; /* half the 670 nm of a common AFM laser diode */
    p->piezo_hysteresis_length_m = 1e-6; /* open-loop tube and stack scanners: a loop over a µm of travel */
    p->piezo_creep_t0_s = 0.1;
    p->mains_Hz = 50.0;
}

/* A paper scene: its reduced values r in SI on the frame E*, R and m = 1e-12 kg. */
static void s_paper(vafm_params *p, double E_star_Pa, double R_m, const vafm_reduced *r)
{
    s_common(p);
    p->E_star_Pa = E_star_Pa;
    p->R_m = R_m;
    p->m_kg = 1e-12;
    vafm_units_from_reduced(p, r);
}

/* The paper's Fig. 1/2 scene: m̃ = 5e-5, ṽ = 1e-4, k̃ = 2e-5, k_BT̃ = 5e-8, γ̃ = 1.2e-4 with
 * E* = 20 GPa, R = 15.7 nm, m = 1e-12 kg (k = 6.28 mN/m, v = 196 nm/s, T ≈ 280 K; the paper rounds
 * to 6.3 mN/m and quotes 288.4 K: reduced values are kept exact here). */
static void s_fill_fig1(vafm_params *p)
{
    const vafm_reduced r = { .m = 5e-5, .k = 2e-5, .kT = 5e-8, .gamma = 1.2e-4,
                             .v_approach = 1e-4, .v_retract = 1e-4 };
    s_paper(p, 20e9, 15.7e-9, &r);
    p->start_height_m = 20e-9;
    p->setpoint_N = 1e-9;
    p->trigger_height_m = -100e-9;
    p->retract_margin_m = 20e-9;
    p->sample_rate_Hz = 2000;
    p->tune_duration_s = 0.5;
}

/* The paper's Fig. 4–6 scene (Langevin, m̃ = 0.01): γ̃ = 0.229, k̃ = 0.1, k_BT̃ = 0.01, ṽ = 1e-3
 * with E* = 1 GPa, R = 16 nm, m = 1e-12 kg (so ṽ = 1e-5 … 0.5 maps to 64 nm/s … 3.2 mm/s). */
static void s_fill_fig4(vafm_params *p)
{
    const vafm_reduced r = { .m = 0.01, .k = 0.1, .kT = 0.01, .gamma = 0.229,
                             .v_approach = 1e-3, .v_retract = 1e-3 };
    s_paper(p, 1e9, 16e-9, &r);
    const vafm_scale sc = vafm_units_scale(p);
    p->start_height_m = vafm_scale_length_si(&sc, 2.0);
    p->setpoint_N = vafm_scale_force_si(&sc, 0.5 * (3.0 * M_PI * r.gamma / 2.0));
    p->trigger_height_m = vafm_scale_length_si(&sc, -1.0);
    p->retract_margin_m = vafm_scale_length_si(&sc, 1.0);
    p->sample_rate_Hz = 1.0 / vafm_scale_time_si(&sc, 2.0); /* one sample per 2 reduced time units */
    p->tune_duration_s = vafm_scale_time_si(&sc, 2e4);
}

/* The same with Brownian dynamics at friction ζ = mη = 1 (reduced), as the paper's Fig. 4/6. */
static void s_fill_fig4_bd(vafm_params *p)
{
    s_fill_fig4(p);
    vafm_reduced r;
    vafm_units_reduce(p, &r);
    r.m = 1.0;
    vafm_units_from_reduced(p, &r);
    const vafm_scale sc = vafm_units_scale(p);
    p->integrator = vafm_integrator_brownian;
    p->sample_rate_Hz = 1.0 / vafm_scale_time_si(&sc, 2.0);
    p->tune_duration_s = vafm_scale_time_si(&sc, 2e4);
}

/* ---- instrument presets: real measurements at room temperature, in an instrument's words (issue #16).
 * Typical values, each with its source; the cantilever is given by k, f0 and Q (the mass and friction
 * follow), the detector by its InvOLS. E* is the contact modulus 1/E* = (1-ν1²)/E1 + (1-ν2²)/E2 and γ the
 * work of adhesion of the JKR model (F_JKR = 3πγR/2). */

/* The values in which the instrument presets differ (s_instrument() sets the rest). The last three are
 * exceptions: 0 or NULL takes the instruments' common value. */
typedef struct s_instrument_row {
    double E_star_Pa, R_m, gamma_J_per_m2;
    double k_N_per_m, f0_Hz, Q;
    double v_m_per_s; /* approach and retract */
    double start_height_m, ramp_size_m, setpoint_N, trigger_height_m;
    double sample_rate_Hz, sensitivity_m_per_V;
    const vafm_contact_type *const *contact; /* NULL: JKR */
    double T_K;                              /* 0: 298.15 K, 25 °C */
    double retract_margin_m;                 /* 0: 100 nm */
} s_instrument_row;

static void s_instrument(vafm_params *p, const s_instrument_row *r)
{
    s_common(p);
    p->T_K = r->T_K > 0 ? r->T_K : 298.15;
    p->m_kg = 1e-12; /* not used: f0 sets the mass */
    p->eta_per_s = 1e3; /* not used: Q sets the friction */
    p->retract_margin_m = r->retract_margin_m > 0 ? r->retract_margin_m : 100e-9;
    p->tune_duration_s = 0.5;
    if (r->contact)
        p->contact = *r->contact;
    p->E_star_Pa = r->E_star_Pa;
    p->R_m = r->R_m;
    p->gamma_J_per_m2 = r->gamma_J_per_m2;
    p->k_N_per_m = r->k_N_per_m;
    p->f0_Hz = r->f0_Hz;
    p->Q = r->Q;
    p->v_approach_m_per_s = p->v_retract_m_per_s = r->v_m_per_s;
    p->start_height_m = r->start_height_m;
    p->ramp_size_m = r->ramp_size_m;
    p->setpoint_N = r->setpoint_N;
    p->trigger_height_m = r->trigger_height_m;
    p->sample_rate_Hz = r->sample_rate_Hz;
    p->sensitivity_m_per_V = r->sensitivity_m_per_V;
}

/* One row per instrument preset. Columns: E* (Pa), R (m), γ (J/m²); k (N/m), f0 (Hz), Q; v (m/s); start
 * height, ramp size (m), setpoint (N), trigger height (m); sample rate (Hz), InvOLS (m/V); then the exceptions
 * to the instruments' common values: contact (NULL: JKR), T (K; 0: 25 °C), retract margin (m; 0: 100 nm). */
enum { S_CONTACT_SILICA, S_CELL_LIQUID, S_COLLOID_PDMS, S_STIFF_POLYMER };
static const s_instrument_row s_instruments[] = {
    /* A soft contact-mode cantilever on silica in air: k = 0.1 N/m, f0 = 13 kHz, Q = 30 (silicon contact
     * levers in air: NanoWorld CONT 0.2 N/m, 13 kHz; Bruker MLCT 0.01-0.6 N/m, 7-125 kHz; Q ~ 10-100 in air),
     * a silicon tip of 10 nm on fused silica (E = 169 and 73 GPa, ν = 0.27 and 0.17: E* = 53 GPa), work of
     * adhesion 0.05 J/m² (silica in ambient air, tens of mJ/m²: F_JKR = 2.4 nN), InvOLS 60 nm/V; a fixed 200 nm
     * ramp at 1 µm/s from 100 nm above the surface, a 5 nN setpoint, 10 kHz sampling. The tools' default.
     * The setpoint lies ~150 nm down; the retract returns to +100 nm. */
    [S_CONTACT_SILICA] = { 53e9, 10e-9, 0.05, 0.1, 13e3, 30, 1e-6, 100e-9, 200e-9, 5e-9, -20e-9, 10e3, 60e-9, NULL, 0, 0 },
    /* A sharp tip on a living cell in buffer: k = 0.03 N/m, f0 = 3 kHz and Q = 2 in liquid (Bruker MLCT-C:
     * 0.01 N/m, 7 kHz in air, about a third of it and Q ~ 1-3 in water), R = 20 nm, a cell of E = 5 kPa
     * (1-10 kPa for fibroblasts and epithelial cells; ν = 0.5: E* = 6.7 kPa), no adhesion (Hertz: model only
     * what it needs), 310 K; a fixed 1.5 µm ramp at 2 µm/s from 300 nm above, a 0.5 nN setpoint, 5 kHz sampling.
     * The indentation at the setpoint is ~0.55 µm, ~0.87 µm of travel. */
    [S_CELL_LIQUID] = { 6.7e3, 20e-9, 0, 0.03, 3e3, 2, 2e-6, 300e-9, 1.5e-6, 0.5e-9, -500e-9, 5e3, 40e-9,
                        &vafm_contact_hertz, 310.15 /* 37 °C */, 300e-9 },
    /* A colloidal probe on PDMS in air: a 5 µm silica bead (R = 2.5 µm) on a tipless lever of k = 2 N/m, f0 = 50 kHz,
     * Q = 50 (tipless levers for colloidal probes: 0.1-5 N/m; NanoWorld TL-FM 2.8 N/m, 75 kHz), Sylgard-184-like
     * PDMS of E = 1 MPa (ν = 0.5: E* = 1.33 MPa; 0.5-3 MPa by cure), work of adhesion 0.04 J/m² (JKR tests of
     * PDMS against silica: 40-50 mJ/m²; F_JKR = 0.47 µN), InvOLS 30 nm/V; a fixed 2 µm ramp at 2 µm/s from 500 nm
     * above the surface, a 200 nN setpoint, 20 kHz sampling. */
    [S_COLLOID_PDMS] = { 1.33e6, 2.5e-6, 0.04, 2.0, 50e3, 50, 2e-6, 500e-9, 2e-6, 200e-9, -200e-9, 20e3, 30e-9, NULL, 0, 0 },
    /* A stiff cantilever on a glassy polymer in air: k = 40 N/m, f0 = 300 kHz, Q = 400 (tapping-mode levers:
     * Bruker RTESPA-300 40 N/m, 300 kHz; NanoWorld NCH 42 N/m, 320 kHz; Q ~ 300-600 in air), an 8 nm silicon
     * tip on polystyrene (E = 3.0 GPa, ν = 0.35, with the tip's own compliance E* = 3.4 GPa), work of adhesion
     * 0.06 J/m² (F_JKR = 2.3 nN, 0.06 nm of deflection: the stiff lever barely shows adhesion), InvOLS 80 nm/V;
     * a fixed 100 nm ramp at 1 µm/s from 40 nm above the surface, a 200 nN setpoint (~6 nm indentation),
     * 50 kHz sampling. */
    [S_STIFF_POLYMER] = { 3.4e9, 8e-9, 0.06, 40.0, 300e3, 400, 1e-6, 40e-9, 100e-9, 200e-9, -10e-9, 50e3, 80e-9, NULL, 0, 0 },
};

static const s_preset s_presets[] = {
    { "paper-fig1", "the paper's reduced Fig. 1/2 scene in SI (the library's reference): 20 GPa, 15.7 nm tip, 6.3 mN/m, ~280 K, "
                    "196 nm/s", s_fill_fig1, NULL },
    { "paper-fig4", "the paper's reduced Fig. 4/5 scene, Langevin: gamma 0.229, k 0.1, m 0.01, kT 0.01, v 1e-3 "
                    "(in SI ~3e6 K: a theory scene, not an instrument)", s_fill_fig4, NULL },
    { "paper-fig4-bd", "the paper's reduced Fig. 4/6 scene, Brownian dynamics with zeta = m*eta = 1",
      s_fill_fig4_bd, NULL },
    { "contact-silica", "instrument: soft contact lever (0.1 N/m, 13 kHz, Q 30) on silica in air, 10 nm Si tip, "
                        "25 C, 1 um/s, 5 nN", NULL, &s_instruments[S_CONTACT_SILICA] },
    { "cell-liquid", "instrument: soft lever in buffer (0.03 N/m, 3 kHz, Q 2), 20 nm tip on a 5 kPa cell (Hertz), "
                     "37 C, 2 um/s, 0.5 nN", NULL, &s_instruments[S_CELL_LIQUID] },
    { "colloid-pdms", "instrument: 5 um silica bead on a 2 N/m lever (50 kHz, Q 50) on PDMS (E 1 MPa, 40 mJ/m^2) in "
                      "air, 25 C, 2 um/s, 200 nN", NULL, &s_instruments[S_COLLOID_PDMS] },
    { "stiff-polymer", "instrument: stiff lever (40 N/m, 300 kHz, Q 400), 8 nm tip on polystyrene (E 3 GPa) in air, "
                       "25 C, 1 um/s, 200 nN", NULL, &s_instruments[S_STIFF_POLYMER] },
};
#define S_NPRESETS ((int)(sizeof s_presets / sizeof s_presets[0]))

void vafm_params_default(vafm_params *p)
{
    s_fill_fig1(p);
}

int vafm_preset_count(void)
{
    return S_NPRESETS;
}

const char *vafm_preset_name(int i)
{
    return i >= 0 && i < S_NPRESETS ? s_presets[i].name : NULL;
}

const char *vafm_preset_description(int i)
{
    return i >= 0 && i < S_NPRESETS ? s_presets[i].description : NULL;
}

int vafm_preset_apply(vafm_params *p, const char *name, vafm_error *err)
{
    for (int i = 0; i < S_NPRESETS; i++)
        if (name && !strcmp(name, s_presets[i].name)) {
            if (s_presets[i].inst)
                s_instrument(p, s_presets[i].inst);
            else
                s_presets[i].fill(p);
            return 0;
        }
    char known[512] = "";
    for (int i = 0; i < S_NPRESETS; i++)
        snprintf(known + strlen(known), sizeof known - strlen(known), "%s%s", i ? ", " : "", s_presets[i].name);
    vafm_err_set(err, VAFM_ENOTFOUND, "preset", "unknown preset '%s' (known: %s)", name ? name : "(null)", known);
    return VAFM_ENOTFOUND;
}
