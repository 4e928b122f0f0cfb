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
