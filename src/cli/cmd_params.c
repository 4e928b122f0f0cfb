/* SPDX-License-Identifier: MIT */
/* `vafm params`, `vafm presets`, `vafm integrators`. */
#include "cli/cli.h"

/* ---- vafm params / presets / integrators ------------------------------------------------------ */

static int s_print_json(const vafm_params *p)
{
    for (size_t len = 4096; len <= (1u << 20); len *= 2) {
        char *buf = malloc(len);
        if (!buf)
            break;
        int n = vafm_params_to_json(p, buf, len);
        if (n >= 0)
            puts(buf);
        free(buf);
        if (n >= 0)
            return VAFM_CLI_EXIT_OK;
    }
    vafm_cli_error("cannot serialise the scene");
    return VAFM_CLI_EXIT_RUNTIME;
}

/* The same scene as an instrument's dialog shows it, and in the paper's reduced units. */
static void s_print_views(const vafm_params *p)
{
    const double m = vafm_params_mass_kg(p), eta = vafm_params_eta_per_s(p), w0 = sqrt(p->k_N_per_m / m);
    printf("\ninstrument view\n");
    printf("  cantilever           k %.4g N/m, f0 %.6g kHz, Q %.4g (mass %.4g kg, friction rate %.4g 1/s)\n",
           p->k_N_per_m, w0 / (2.0 * M_PI) * 1e-3, w0 / eta, m, eta);
    printf("  detector             InvOLS %.4g nm/V, noise %.3g mV rms, %s, offset %.4g V\n",
           p->sensitivity_m_per_V * 1e9, p->noise_V_rms * 1e3, p->adc_bits ? "ADC" : "no ADC", p->baseline_offset_V);
    printf("  temperature          %.2f K (%.2f C)\n", p->T_K, p->T_K - 273.15);
    if (p->ramp_size_m > 0)
        printf("  ramp                 size %.4g nm from %s, extend %.4g s at %.4g um/s, retract %.4g s at %.4g um/s\n",
               p->ramp_size_m * 1e9, p->ramp_start == VAFM_RAMP_START_TRIGGER ? "the trigger point" : "start_height_m",
               p->ramp_size_m / p->v_approach_m_per_s, p->v_approach_m_per_s * 1e6,
               p->ramp_size_m / p->v_retract_m_per_s, p->v_retract_m_per_s * 1e6);
    else
        printf("  ramp                 adaptive from %.4g nm above the surface, approach %.4g um/s, retract %.4g um/s "
               "until %.4g nm past the detachment\n",
               p->start_height_m * 1e9, p->v_approach_m_per_s * 1e6, p->v_retract_m_per_s * 1e6,
               p->retract_margin_m * 1e9);
    if (p->trigger == VAFM_TRIGGER_FORCE)
        printf("  trigger              %s setpoint %.4g nN = %.4g V of deflection signal\n",
               p->setpoint_mode == VAFM_SETPOINT_RELATIVE ? "relative" : "absolute", p->setpoint_N * 1e9,
               p->setpoint_N / (p->k_N_per_m * p->sensitivity_m_per_V) +
                   (p->setpoint_mode == VAFM_SETPOINT_RELATIVE ? 0.0 : p->baseline_offset_V));
    else
        printf("  trigger              height %.4g nm\n", p->trigger_height_m * 1e9);
    printf("  sampling             %.6g Hz", p->sample_rate_Hz);
    if (p->ramp_size_m > 0)
        printf(", %.0f samples per extend", p->sample_rate_Hz * p->ramp_size_m / p->v_approach_m_per_s);
    printf("; dwell %.4g s at constant %s\n", p->dwell_s, p->dwell_mode == VAFM_DWELL_FORCE ? "force" : "height");
    vafm_reduced r;
    vafm_units_reduce(p, &r);
    vafm_scale sc = vafm_units_scale(p);
    printf("\nreduced view (the paper's units: length R, time 1/eta, force E*R^2)\n");
    printf("  m %.6g  k %.6g  kT %.6g  gamma %.6g  v_approach %.6g  v_retract %.6g  eta_cont %.6g\n", r.m, r.k, r.kT,
           r.gamma, r.v_approach, r.v_retract, r.eta_cont);
    printf("  units: length %.4g m, time %.4g s, force %.4g N, speed %.4g m/s\n", sc.length_m, sc.time_s, sc.force_N,
           sc.speed_m_per_s);
}

int vafm_cli_cmd_params(const vafm_cli_args *a)
{
    vafm_cli_scene sc;
    int rc = vafm_cli_resolve_scene(a, &sc, 1);
    if (rc)
        return rc;
    if (a->on[O_JSON])
        return s_print_json(&sc.p);
    vafm_cli_print_provenance(stdout, &sc);
    char val[128];
    for (int i = 0; i < vafm_params_field_count(); i++) {
        const vafm_param_info *f = vafm_params_field_at(i);
        vafm_params_get(&sc.p, f->name, val, sizeof val);
        printf("  %-20s %-24s %-6s %s\n", f->name, val, f->unit[0] ? f->unit : "-", f->doc);
    }
    s_print_views(&sc.p);
    return VAFM_CLI_EXIT_OK;
}

int vafm_cli_cmd_presets(const vafm_cli_args *a)
{
    (void)a;
    for (int i = 0; i < vafm_preset_count(); i++)
        printf("%-16s %s%s\n", vafm_preset_name(i), vafm_preset_description(i),
               strcmp(vafm_preset_name(i), VAFM_CLI_DEFAULT_PRESET) ? "" : " [default]");
    return VAFM_CLI_EXIT_OK;
}

int vafm_cli_cmd_integrators(const vafm_cli_args *a)
{
    (void)a;
    for (int i = 0; i < vafm_integrator_count(); i++) {
        const vafm_integrator_type *t = vafm_integrator_at(i);
        printf("%-10s %s (%s, stability limit %g)\n", t->name, t->description,
               t->overdamped ? "overdamped" : "underdamped", t->stability_limit);
    }
    return VAFM_CLI_EXIT_OK;
}
