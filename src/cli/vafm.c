/* SPDX-License-Identifier: MIT */
/*
 * vafm: the command-line tool's entry: the one command table, the option parser, help and main (the
 * commands themselves live in cmd_*.c; cli.h says how the tool is laid out).
 * vafm is a thin layer over the library: it resolves a scene (preset, JSON scene
 * file, --NAME=VALUE overrides, in that order), runs curves through vafm_sim / vafm_campaign_run, and
 * prints what came out. No physics here: every number shown is either a library result or a unit
 * conversion of one (F_JKR = 3πγR/2 is the force unit the physics notes use). campaign, info and
 * export write and read HDF5 force-curve files through h5/h5.h (protocol/hdf5.md).
 *
 * Exit status: 0 success, 1 runtime error (a curve failed, I/O, a damaged file), 2 usage or parameter
 * error. Every parameter error repeats the library's vafm_error message, which names the field, value
 * and range.
 */
#include <signal.h>

#include "cli/cli.h"
#include "cli/cmd_client.h"
#include "cli/cmd_web.h"
#include "cli/study.h"

/* ---- options ---------------------------------------------------------------------------------- */

typedef struct s_option {
    const char *name;  /* long form */
    const char *alias; /* short form, or NULL */
    int has_value;
} s_option;

static const s_option s_options[VAFM_CLI_NOPT] = {
    [O_HELP] = { "--help", "-h", 0 },       [O_VERSION] = { "--version", NULL, 0 },
    [O_QUIET] = { "--quiet", "-q", 0 },     [O_PROGRESS] = { "--progress", NULL, 0 },
    [O_PRESET] = { "--preset", NULL, 1 },   [O_SCENE] = { "--scene", NULL, 1 },
    [O_INDEX] = { "--index", NULL, 1 },     [O_N] = { "-n", NULL, 1 },
    [O_THREADS] = { "--threads", NULL, 1 }, [O_FIRST] = { "--first", NULL, 1 },
    [O_CSV] = { "--csv", NULL, 1 },         [O_T] = { "--T", NULL, 1 },
    [O_V] = { "--v", NULL, 1 },             [O_K] = { "--k", NULL, 1 },
    [O_JSON] = { "--json", NULL, 0 },       [O_TUNE] = { "--tune", NULL, 0 },
    [O_OUT] = { "--out", "-o", 1 },         [O_RESUME] = { "--resume", NULL, 0 },
    [O_OVERWRITE] = { "--overwrite", NULL, 0 }, [O_FLUSH] = { "--flush-interval", NULL, 1 },
    [O_GZIP] = { "--gzip", NULL, 1 },       [O_CURVE] = { "--curve", NULL, 1 },
    [O_MPI] = { "--mpi", NULL, 0 },
    [O_NX] = { "--nx", NULL, 1 },           [O_NY] = { "--ny", NULL, 1 },
    [O_SIZE] = { "--size", NULL, 1 },       [O_PATTERN] = { "--pattern", NULL, 1 },
    [O_PPARAM] = { "--pattern-param", NULL, 1 },
    [O_SAMPLE] = { "--sample", NULL, 1 },  [O_KERNEL] = { "--kernel", NULL, 1 },
    [O_SEGMENTS] = { "--segments", NULL, 1 },
};

#define M(o) (1u << (o))
#define S_GENERAL (M(O_HELP) | M(O_VERSION))
#define S_SCENE_OPTS (M(O_PRESET) | M(O_SCENE))


static const vafm_cli_command *s_command_at(int i);
static const vafm_cli_command *s_command_find(const char *name);

/* ---- argument parsing ------------------------------------------------------------------------- */

static int s_find_option(const char *name, size_t len)
{
    for (int i = 0; i < VAFM_CLI_NOPT; i++) {
        const s_option *o = &s_options[i];
        if ((strlen(o->name) == len && !strncmp(o->name, name, len)) ||
            (o->alias && strlen(o->alias) == len && !strncmp(o->alias, name, len)))
            return i;
    }
    return -1;
}

/* The words of an instrument's force-curve dialog, as options: each names the field(s) of the table it sets
 * (values take units: --setpoint 1nN, --speed 2um/s, --f0 70kHz, --T 25C). */
static const struct {
    const char *alias, *field, *field2;
} s_aliases[] = {
    { "setpoint", "setpoint_N", NULL },     { "ramp-size", "ramp_size_m", NULL },
    { "ramp-rate", "ramp_rate_Hz", NULL },  { "speed", "v_approach_m_per_s", "v_retract_m_per_s" },
    { "f0", "f0_Hz", NULL },                { "invols", "sensitivity_m_per_V", NULL },
    { "rate", "sample_rate_Hz", NULL },     { "dwell", "dwell_s", NULL },
    { "radius", "R_m", NULL },
};

static vafm_cli_override *s_add_override(vafm_cli_args *a, const char *opt, const char *field, const char *value)
{
    vafm_cli_override *o = &a->ov[a->n_ov++];
    snprintf(o->name, sizeof o->name, "%s", field);
    snprintf(o->opt, sizeof o->opt, "--%s", opt);
    o->value = value;
    o->axis = 0;
    return o;
}

/* `--NAME=VALUE` or `--NAME VALUE` for a parameter of the table or one of its instrument words. */
static int s_parse_override(vafm_cli_args *a, const char *arg, size_t len, const char *value)
{
    const char *name = arg + 2;
    size_t nlen = len - 2;
    char buf[64];
    if (nlen >= sizeof buf) {
        vafm_cli_error("unknown option '%.*s' (see vafm --help)", (int)len, arg);
        return VAFM_CLI_EXIT_USAGE;
    }
    memcpy(buf, name, nlen);
    buf[nlen] = '\0';
    const char *f1 = NULL, *f2 = NULL;
    for (size_t i = 0; i < sizeof s_aliases / sizeof s_aliases[0]; i++)
        if (!strcmp(buf, s_aliases[i].alias)) {
            f1 = s_aliases[i].field;
            f2 = s_aliases[i].field2;
        }
    if (!f1 && vafm_params_field_find(buf))
        f1 = buf;
    if (!f1) {
        vafm_cli_error("unknown option or parameter '%.*s' (see vafm --help for the PARAMETERS list)", (int)len, arg);
        return VAFM_CLI_EXIT_USAGE;
    }
    if (!value) {
        vafm_cli_error("parameter --%s needs a value (--%s=VALUE or --%s VALUE)", buf, buf, buf);
        return VAFM_CLI_EXIT_USAGE;
    }
    s_add_override(a, buf, f1, value);
    if (f2)
        s_add_override(a, buf, f2, value);
    return 0;
}

static int s_parse_option(vafm_cli_args *a, int argc, char **argv, int *i)
{
    const char *arg = argv[*i];
    const char *eq = strchr(arg, '=');
    size_t len = eq ? (size_t)(eq - arg) : strlen(arg);
    const char *inline_value = eq ? eq + 1 : NULL;
    int id = s_find_option(arg, len);
    if (id < 0) {
        if (strncmp(arg, "--", 2) != 0 || len <= 2) {
            vafm_cli_error("unknown option '%s' (see vafm --help)", arg);
            return VAFM_CLI_EXIT_USAGE;
        }
        const char *value = inline_value ? inline_value : *i + 1 < argc ? argv[++*i] : NULL;
        return s_parse_override(a, arg, len, value);
    }
    const s_option *o = &s_options[id];
    if (a->on[id] && o->has_value) {
        vafm_cli_error("option %s is given twice", o->name);
        return VAFM_CLI_EXIT_USAGE;
    }
    a->on[id] = 1;
    if (!o->has_value) {
        if (inline_value) {
            vafm_cli_error("option %s takes no value", o->name);
            return VAFM_CLI_EXIT_USAGE;
        }
        return 0;
    }
    if (!inline_value && *i + 1 >= argc) {
        vafm_cli_error("option %s needs a value", o->name);
        return VAFM_CLI_EXIT_USAGE;
    }
    a->val[id] = inline_value ? inline_value : argv[++*i];
    /* --T, --v and --k are a campaign's grid axes; for a single scene they set the temperature, both speeds
     * and the spring constant, in command-line order like every override (the last value of a field wins):
     * they take their place among the overrides now, and s_check_options drops them where they are axes */
    static const struct {
        int id;
        const char *f1, *f2;
    } axes[] = { { O_T, "T_K", NULL }, { O_V, "v_approach_m_per_s", "v_retract_m_per_s" }, { O_K, "k_N_per_m", NULL } };
    for (size_t k = 0; k < sizeof axes / sizeof axes[0]; k++)
        if (axes[k].id == id) {
            s_add_override(a, s_options[id].name + 2, axes[k].f1, a->val[id])->axis = 1 + id;
            if (axes[k].f2)
                s_add_override(a, s_options[id].name + 2, axes[k].f2, a->val[id])->axis = 1 + id;
        }
    return 0;
}

static int s_parse_positional(vafm_cli_args *a, const char *arg)
{
    if (!a->cmd) {
        a->cmd = s_command_find(arg);
        a->explicit_cmd = 1;
        if (!a->cmd) {
            vafm_cli_error("unknown command '%s' (see vafm --help)", arg);
            return VAFM_CLI_EXIT_USAGE;
        }
        return 0;
    }
    if (!strcmp(a->cmd->name, "help") && !a->topic) {
        a->topic = arg;
        return 0;
    }
    if (a->cmd->file && !a->file) {
        a->file = arg;
        return 0;
    }
    vafm_cli_error("unexpected argument '%s' (see vafm --help)", arg);
    return VAFM_CLI_EXIT_USAGE;
}

/* Every option given must belong to the command; parameter overrides only to scene commands. */
static int s_check_options(vafm_cli_args *a)
{
    const vafm_cli_command *c = a->cmd;
    /* --T, --v and --k: a grid axis where the command takes the option (its list is in a->val), else, for a
     * single scene, the overrides s_parse_option put in their place */
    int n = 0;
    for (int i = 0; i < a->n_ov; i++) {
        int id = a->ov[i].axis - 1;
        if (id >= 0 && (!c->scene || (c->opts & M(id))))
            continue;
        a->ov[n++] = a->ov[i];
    }
    a->n_ov = n;
    if (c->scene)
        for (int id = O_T; id <= O_K; id++) /* O_T, O_V, O_K: adjacent in the enum */
            if (a->on[id] && !(c->opts & M(id))) {
                a->on[id] = 0;
                a->val[id] = NULL;
            }
    for (int id = 0; id < VAFM_CLI_NOPT; id++)
        if (a->on[id] && !(c->opts & M(id)) && !(c->scene && (S_SCENE_OPTS & M(id)))) {
            vafm_cli_error("option %s does not apply to `vafm %s` (see vafm %s --help)", s_options[id].name, c->name,
                    c->name);
            return VAFM_CLI_EXIT_USAGE;
        }
    if (a->n_ov && !c->scene) {
        vafm_cli_error("parameter --%s does not apply to `vafm %s`", a->ov[0].name, c->name);
        return VAFM_CLI_EXIT_USAGE;
    }
    return 0;
}

static int s_parse_args(vafm_cli_args *a, int argc, char **argv)
{
    memset(a, 0, sizeof *a);
    a->ov = calloc(2 * (size_t)argc + 8, sizeof *a->ov); /* an alias or --v sets two fields per argument */
    if (!a->ov) {
        vafm_cli_error("out of memory");
        return VAFM_CLI_EXIT_RUNTIME;
    }
    for (int i = 1; i < argc; i++) {
        int r = argv[i][0] == '-' && argv[i][1] != '\0' ? s_parse_option(a, argc, argv, &i)
                                                        : s_parse_positional(a, argv[i]);
        if (r)
            return r;
    }
    if (!a->cmd)
        a->cmd = s_command_find("run");
    if (!a->cmd)
        return VAFM_CLI_EXIT_USAGE; /* unreachable: "run" is in the table */
    return a->on[O_HELP] || a->on[O_VERSION] ? 0 : s_check_options(a);
}

/* ---- help ------------------------------------------------------------------------------------- */

static void s_print_param_help(FILE *o)
{
    vafm_params def;
    vafm_preset_apply(&def, VAFM_CLI_DEFAULT_PRESET, NULL);
    fprintf(o, "\nPARAMETERS (--NAME=VALUE or --NAME VALUE; also the keys of a --scene file)\n"
               "  name                 unit   allowed                          default (%s)\n",
            VAFM_CLI_DEFAULT_PRESET);
    char allowed[160], val[128], shown[64];
    for (int i = 0; i < vafm_params_field_count(); i++) {
        const vafm_param_info *f = vafm_params_field_at(i);
        vafm_params_get(&def, f->name, val, sizeof val);
        if (f->kind == VAFM_PARAM_REAL) {
            snprintf(allowed, sizeof allowed, "[%.6g, %.6g]", f->min, f->max);
            snprintf(shown, sizeof shown, "%.6g", strtod(val, NULL));
        } else {
            /* an INT field has its own range in the table (adc_bits [0, 24], segment_samples [0, 16777216]);
             * only the seed spans all of uint64 */
            if (f->kind == VAFM_PARAM_INT)
                snprintf(allowed, sizeof allowed, "integer [%.0f, %.0f]", f->min, f->max);
            else
                snprintf(allowed, sizeof allowed, "%s",
                         f->kind == VAFM_PARAM_CHOICE ? f->choices
                         : f->kind == VAFM_PARAM_BOOL ? "true|false"
                                                      : "integer [0, 2^64-1]");
            snprintf(shown, sizeof shown, "%.63s", val);
        }
        fprintf(o, "  %-20s %-6s %-32s %s\n  %-20s %s\n", f->name, f->unit[0] ? f->unit : "-", allowed, shown, "",
                f->doc);
    }
}

static const char s_scene_help[] =
    "\nSCENE (run, curves, samples, params, campaign), applied in this order:\n"
    "  --preset NAME        start from a preset (default " VAFM_CLI_DEFAULT_PRESET "; see `vafm presets`)\n"
    "  --scene FILE.json    apply a JSON object {\"preset\": NAME, \"<parameter>\": value, ...};\n"
    "                       its preset comes first; `vafm params --json` writes one\n"
    "  --NAME=VALUE         set a parameter (see PARAMETERS); also --NAME VALUE; in command-line order;\n"
    "                       values may carry the field's unit with an SI prefix: 1nN, 2um/s, 70kHz, 25C\n"
    "  the instrument's words set the same parameters:\n"
    "    --setpoint F       setpoint_N (1nN)             --ramp-size Z    ramp_size_m (1um: a fixed ramp)\n"
    "    --speed V          both speeds (2um/s)          --ramp-rate R    ramp_rate_Hz (1Hz)\n"
    "    --f0 F             f0_Hz (70kHz)                --Q Q            quality factor\n"
    "    --invols S         sensitivity_m_per_V (60nm/V) --rate R         sample_rate_Hz (10kHz)\n"
    "    --dwell T          dwell_s (0.5s)               --radius R       R_m (10nm)\n"
    "    --T T, --v V, --k K  temperature, both speeds, spring constant (a campaign's lists: --T 15C,25C,35C)\n"
    "  then extend_time_s/retract_time_s/ramp_rate_Hz set the speeds, segment_samples the sample rate and\n"
    "  setpoint_V the setpoint (vafm_params_resolve)\n";

static const char s_exit_help[] = "\nEXIT STATUS\n"
                                  "  0 success, 1 runtime error (a curve failed, output failed,\n"
                                  "  a file is damaged or unreadable),\n"
                                  "  2 usage or parameter error (the message names the field, value and range)\n";

static void s_print_usage(FILE *o)
{
    fprintf(o, "vafm %s: a virtual AFM (thermal JKR pull-off force curves)\n\nUSAGE\n"
               "  vafm [COMMAND] [OPTIONS]     (no command: run)\n\nCOMMANDS\n",
            vafm_version());
    for (int i = 0; s_command_at(i); i++) {
        const vafm_cli_command *c = s_command_at(i);
        if (c->main)
            fprintf(o, "  %-12s %s  (vafm %s --help)\n", c->name, c->summary, c->name);
        else
            fprintf(o, "  %-12s %s\n", c->name, c->summary);
    }
    for (int i = 0; s_command_at(i); i++)
        if (s_command_at(i)->usage)
            fprintf(o, "\n%s", s_command_at(i)->usage);
    fprintf(o, "\nCOMMON OPTIONS\n  -h, --help           this text (vafm COMMAND --help: that command's)\n"
               "  --version            print the version\n");
    fputs(s_scene_help, o);
    fputs(s_exit_help, o);
    s_print_param_help(o);
}

static void s_print_command_help(FILE *o, const vafm_cli_command *c)
{
    fprintf(o, "vafm %s: %s\n\n%s", c->name, c->summary, c->usage ? c->usage : "");
    if (c->opts & M(O_KERNEL)) { /* the names of the batch kernel's backend table */
        char names[128];
        vafm_campaign_spec sp;
        memset(&sp, 0, sizeof sp);
        vafm_campaign_kernel_names(names, sizeof names, ", ");
        fprintf(o, "\nKERNELS (--kernel)\n  %s (auto on this CPU: %s)\n", names, vafm_campaign_kernel_describe(&sp));
    }
    if (c->scene) {
        fputs(s_scene_help, o);
        fputs(s_exit_help, o);
        s_print_param_help(o);
    }
}

static int s_cmd_help(const vafm_cli_args *a)
{
    if (!a->topic) {
        s_print_usage(stdout);
        return VAFM_CLI_EXIT_OK;
    }
    const vafm_cli_command *c = s_command_find(a->topic);
    if (c && c->main) {
        char *argv[] = { (char *)c->name, (char *)"--help", NULL };
        return c->main(2, argv);
    }
    if (!c) {
        vafm_cli_error("help: unknown command '%s'", a->topic);
        return VAFM_CLI_EXIT_USAGE;
    }
    s_print_command_help(stdout, c);
    return VAFM_CLI_EXIT_OK;
}

/* ---- the command table ------------------------------------------------------------------------ */

static const vafm_cli_command s_commands[] = {
    { "run", vafm_cli_cmd_run,
      S_GENERAL | M(O_INDEX) | M(O_PROGRESS) | M(O_QUIET) | M(O_SEGMENTS) | M(O_OUT) | M(O_OVERWRITE), 1,
      "one force curve with a readable summary (the default command)",
      "vafm run [SCENE] [--index N] [--segments FILE.json] [--out FILE.h5 [--overwrite]] [--progress] [--quiet]\n"
      "  --index N            curve index = its random stream (default 0)\n"
      "  --segments FILE      run this segment list instead of the scene's curve (docs/instrument.md, Segments)\n"
      "  -o, --out FILE.h5    also write the curve to an HDF5 file (protocol/hdf5.md; a segment list: format 1.2,\n"
      "                       segment = the segment's position, 'segment count' = the list's length)\n"
      "  --overwrite          replace an existing --out file\n"
      "  --progress           report progress on stderr even when it is not a terminal\n"
      "  -q, --quiet          no progress\n", 0, NULL },
    { "curves", vafm_cli_cmd_curves,
      S_GENERAL | M(O_N) | M(O_THREADS) | M(O_FIRST) | M(O_CSV) | M(O_T) | M(O_V) | M(O_K) | M(O_PROGRESS) |
          M(O_QUIET) | M(O_KERNEL),
      1, "N curves per grid point on all cores: statistics, optional per-curve CSV",
      "vafm curves -n N [SCENE] [--threads T] [--first I] [--csv FILE|-] [--T LIST] [--v LIST] [--k LIST]\n"
      "  -n N                 curves per grid point (required)\n"
      "  --threads T          worker threads (default 0: all cores); results do not depend on it\n"
      "  --kernel NAME        how curves are stepped: auto (default: batch where the CPU has AVX2 or AVX-512),\n"
      "                       scalar (one curve at a time per thread), batch or batchN (curves in SIMD lanes,\n"
      "                       up to N; the names under KERNELS); the results are the same bit for bit\n"
      "  --first I            skip global curve indices below I (resume)\n"
      "  --csv FILE|-         one row per curve (SI); '-' writes to stdout and the summary to stderr\n"
      "  --T LIST             temperatures, K, comma-separated (grid: T slowest, then v, then k)\n"
      "  --v LIST             piezo speeds (approach and retract), m/s\n"
      "  --k LIST             spring constants, N/m\n"
      "  --progress           report progress on stderr even when it is not a terminal\n"
      "  -q, --quiet          no progress (and no summary when the CSV goes to stdout)\n", 0, NULL },
    { "samples", vafm_cli_cmd_samples,
      S_GENERAL | M(O_INDEX) | M(O_CSV) | M(O_TUNE) | M(O_PROGRESS) | M(O_QUIET) | M(O_SEGMENTS), 1,
      "one curve's (or a thermal tune's) output samples as CSV",
      "vafm samples [SCENE] [--index N] [--csv FILE|-] [--tune] [--segments FILE.json]\n"
      "  --index N            curve index (default 0)\n"
      "  --segments FILE      a segment list instead of the scene's curve; segment = the segment's position\n"
      "                       in the list (or its label)\n"
      "  --csv FILE|-         output file (default '-': stdout);\n"
      "                       columns time_s,height_m,deflection_m,force_N,tip_m,segment\n"
      "                       (segment 0 approach, 1 retract, 2 dwell, 3 tune)\n"
      "  --tune               a thermal tune (free cantilever) of tune_duration_s instead of a curve\n", 0, NULL },
    { "params", vafm_cli_cmd_params, S_GENERAL | M(O_JSON), 1, "print the resolved scene as a table or JSON",
      "vafm params [SCENE] [--json]\n"
      "  --json               JSON object (accepted back by --scene)\n", 0, NULL },
    { "presets", vafm_cli_cmd_presets, S_GENERAL, 0, "list the scene presets", "vafm presets\n", 0, NULL },
    { "integrators", vafm_cli_cmd_integrators, S_GENERAL, 0, "list the time integrators", "vafm integrators\n", 0, NULL },
    { "help", s_cmd_help, S_GENERAL, 0, "this text, or one command's (vafm help COMMAND)", NULL, 0, NULL },
    { "campaign", vafm_cli_cmd_campaign,
      S_GENERAL | M(O_N) | M(O_OUT) | M(O_THREADS) | M(O_T) | M(O_V) | M(O_K) | M(O_RESUME) | M(O_OVERWRITE) |
          M(O_FLUSH) | M(O_GZIP) | M(O_PROGRESS) | M(O_QUIET) | M(O_MPI) | M(O_KERNEL),
      1, "a grid of N curves per point on all cores into one HDF5 file (afmformats layout), resumable",
      "vafm campaign -n N --out FILE.h5 [SCENE] [--T LIST] [--v LIST] [--k LIST] [--threads T]\n"
      "              [--resume | --overwrite] [--flush-interval S] [--gzip L] [--progress | --quiet] [--mpi]\n"
      "  -n N                 curves per grid point (required)\n"
      "  -o, --out FILE.h5    the file: one group per curve with its channels, the scene, grid, seed and\n"
      "                       every curve's ground truth (protocol/hdf5.md; read by afmformats, nanite, PyJibe)\n"
      "  --T, --v, --k LIST   grid lists as for vafm curves (K, m/s, N/m; T slowest, then v, then k)\n"
      "  --threads T          worker threads (default 0: all cores); the file does not depend on it\n"
      "  --kernel NAME        how curves are stepped: auto (default: batch where the CPU has AVX2 or AVX-512),\n"
      "                       scalar (one curve at a time per thread), batch or batchN (curves in SIMD lanes,\n"
      "                       up to N; the names under KERNELS); the results are the same bit for bit\n"
      "  --resume             continue FILE (same scene and grid, else refused naming the field): keep its\n"
      "                       complete curves and run the rest; the result equals an uninterrupted run\n"
      "  --overwrite          replace an existing FILE (without --resume or --overwrite it is refused)\n"
      "  --flush-interval S   make the curves durable every S seconds (default 1; 0: as soon as a curve\n"
      "                       waits); a kill -9 loses at most the curves of the last S seconds (and those in\n"
      "                       flight: with the batch kernel up to 16 per thread)\n"
      "  --gzip L             compress the channels: shuffle + deflate at level L (1-9; default 0: off)\n"
      "  --progress           report progress on stderr even when it is not a terminal\n"
      "  -q, --quiet          no progress\n"
      "  --mpi                run on MPI even without an MPI launcher in the environment (under mpirun or\n"
      "                       srun it is implied): `mpirun -np R vafm campaign ...` splits the curves over R\n"
      "                       ranks (x --threads each, default: the rank's share of its node's cores); rank 0\n"
      "                       writes FILE, identical to the single-process file (README: Campaigns on MPI)\n", 0, NULL },
    { "map", vafm_cli_cmd_map,
      S_GENERAL | M(O_NX) | M(O_NY) | M(O_SIZE) | M(O_PATTERN) | M(O_PPARAM) | M(O_SAMPLE) | M(O_OUT) | M(O_THREADS) |
          M(O_RESUME) | M(O_OVERWRITE) | M(O_FLUSH) | M(O_GZIP) | M(O_PROGRESS) | M(O_QUIET) | M(O_MPI) | M(O_KERNEL),
      1, "a force map: one curve per pixel over a heterogeneous sample into one HDF5 file, resumable",
      "vafm map --out FILE.h5 [--nx NX] [--ny NY] [--size S|SX,SY] [--pattern NAME] [--pattern-param LIST]\n"
      "         [SCENE] [--threads T] [--resume | --overwrite] [--flush-interval S] [--gzip L] [--progress | --quiet]\n"
      "  --nx, --ny N         pixels along x and y (default 32 each; 1-1024 each, nx*ny <= 262144)\n"
      "  --size S|SX,SY       scan size, m (default 10e-6 both); pixel (ix, iy) sits at the centre of its cell\n"
      "  --pattern NAME       the sample: uniform (default; the scene's material), stripes (along y, period_m:\n"
      "                       material a then b), disc | dome (a body of material b, radius_m, height_m, on a\n"
      "                       substrate of material a; dome: a spherical cap), domains (a random blend of a and\n"
      "                       b from domain_seed, domain size domain_m, fraction of b)\n"
      "  --sample GRID.h5     a measured map as the sample (pattern grid): E_star_Pa, gamma_J_per_m2, height_m as\n"
      "                       2-D datasets with x0_m, y0_m, dx_m, dy_m (protocol/hdf5.md, Map grids),\n"
      "                       interpolated bilinearly at each pixel on material a's contact model\n"
      "  --pattern-param LIST NAME=VALUE,...: period_m (5e-6), radius_m (3e-6), height_m (0.5e-6), domain_m (1e-6),\n"
      "                       domain_seed (1), fraction (0.5), center_x_m, center_y_m (0), start (surface: the\n"
      "                       approach starts start_height_m above the local surface, the default; fixed: above\n"
      "                       the substrate, so a higher surface is reached sooner), the materials a_contact, a_E_star_Pa,\n"
      "                       a_gamma_J_per_m2 (default: the scene's) and b_... (default: the scene's contact,\n"
      "                       E* 1e9 Pa, gamma 0.02 J/m^2; hertz and none have gamma 0); also nx, ny, size_x_m, size_y_m\n"
      "  -o, --out FILE.h5    the file: one curve per pixel, curve index = iy*nx + ix (its random stream), with\n"
      "                       afmformats' map attributes (grid shape/size/center/index, position) and the\n"
      "                       ground truth (E*, gamma, surface height of each pixel); protocol/hdf5.md\n"
      "  --threads T          worker threads (default 0: all cores); the file does not depend on it\n"
      "  --resume, --overwrite, --flush-interval S, --gzip L, --progress, -q, --mpi, --kernel: as for vafm campaign\n"
      "                       (`mpirun -np R vafm map ...`: the pixels split over R ranks, the file the same)\n", 0, NULL },
    { "info", vafm_cli_cmd_info, S_GENERAL | M(O_JSON), 0,
      "summarise an HDF5 force-curve file (vafm's or another program's) and check its conformance",
      "vafm info FILE [--json]\n"
      "  FILE                 an HDF5 file of the afmformats layout: curves, provenance, per-point\n"
      "                       statistics (vafm files), conformance to protocol/hdf5.md (a broken rule is\n"
      "                       reported; exit 1 only when the file or a curve cannot be read)\n"
      "  --json               print only the scene the file was written with (a --scene file)\n",
      1, NULL },
    { "export", vafm_cli_cmd_export, S_GENERAL | M(O_CURVE) | M(O_CSV), 0, "one curve of an HDF5 file as CSV",
      "vafm export FILE --curve I [--csv OUT|-]\n"
      "  --curve I            the curve: its group number, as vafm info lists them\n"
      "  --csv OUT|-          output file (default '-': stdout); the columns of vafm samples;\n"
      "                       empty where the file lacks the channel (protocol/csv.md)\n",
      1, NULL },
    /* commands that parse their own arguments (network clients, studies, replay): `vafm NAME --help` */
    { "ctl", NULL, 0, 0, "send any command to a running vafmd, print the reply", NULL, 0, vafm_cli_ctl },
    { "status", NULL, 0, 0, "the state of a running vafmd", NULL, 0, vafm_cli_status },
    { "listen", NULL, 0, 0, "record the runs a vafmd streams to CSV or HDF5", NULL, 0, vafm_cli_listen },
    { "web", NULL, 0, 0, "the live web panel of a running vafmd, in any browser (docs/web.md)", NULL, 0,
      vafm_cli_web },
    { "replay", NULL, 0, 0, "replay the curves of an HDF5 file through a running vafmd's stream", NULL, 0,
      vafm_cli_replay },
    { "study", NULL, 0, 0, "reproduce one of the paper's results: campaigns, fits, theory, report, figures", NULL, 0,
      vafm_cmd_study },
    { "theory", NULL, 0, 0, "quasi-static, DHS and MFPT-rate references for a scene, without simulating", NULL, 0,
      vafm_cmd_theory },
};
#define S_NCOMMANDS ((int)(sizeof s_commands / sizeof s_commands[0]))

static const vafm_cli_command *s_command_at(int i)
{
    return i >= 0 && i < S_NCOMMANDS ? &s_commands[i] : NULL;
}

static const vafm_cli_command *s_command_find(const char *name)
{
    for (int i = 0; i < S_NCOMMANDS; i++)
        if (!strcmp(name, s_commands[i].name))
            return &s_commands[i];
    return NULL;
}

/* ---- main ------------------------------------------------------------------------------------- */

static int s_dispatch(const vafm_cli_args *a)
{
    const vafm_cli_command *c = a->cmd;
    if (a->on[O_VERSION]) {
        printf("vafm %s (built against API %d.%d.%d)\n", vafm_version(), VAFM_API_VERSION_MAJOR,
               VAFM_API_VERSION_MINOR, VAFM_API_VERSION_PATCH);
        vafm_campaign_spec sp;
        memset(&sp, 0, sizeof sp);
        printf("campaign kernel on this CPU: %s\n", vafm_campaign_kernel_describe(&sp));
        return VAFM_CLI_EXIT_OK;
    }
    if (a->on[O_HELP]) {
        if (!a->explicit_cmd || c->fn == s_cmd_help)
            s_print_usage(stdout);
        else
            s_print_command_help(stdout, c);
        return VAFM_CLI_EXIT_OK;
    }
    return c->fn(a);
}

int main(int argc, char **argv)
{
    /* A file-size limit (ulimit -f) must be an error naming the file, as a full disk is, not a kill:
     * ignored, SIGXFSZ becomes EFBIG from write(), which the writers report and survive. */
    signal(SIGXFSZ, SIG_IGN);
    const vafm_cli_command *ext = argc > 1 ? s_command_find(argv[1]) : NULL;
    if (ext && ext->main) {
        int erc = ext->main(argc - 1, argv + 1);
        if (fflush(stdout) != 0 && !erc) {
            vafm_cli_error("writing to stdout failed");
            erc = VAFM_CLI_EXIT_RUNTIME;
        }
        return erc;
    }
    vafm_cli_args a;
    int rc = s_parse_args(&a, argc, argv);
    if (!rc)
        rc = s_dispatch(&a);
    free(a.ov);
    if (fflush(stdout) != 0 && !rc) {
        vafm_cli_error("writing to stdout failed");
        rc = VAFM_CLI_EXIT_RUNTIME;
    }
    return rc;
}
