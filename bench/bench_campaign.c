/* SPDX-License-Identifier: MIT */
/*
 * bench_campaign: what `vafm campaign` delivers, curves/s and MB/s into one HDF5 file, on 1 and 2
 * threads for the paper-fig4 scene at three reduced speeds, and how much of the wall time the writer
 * takes. It reports; it never fails on speed.
 *
 * The command-line tool itself is measured (run as a child process), so the numbers include what a
 * user gets: the campaign's workers, the append of every curve from the delivering worker, the flusher
 * thread (--flush-interval 1 s, the default) and the final close. The tool reports the writer's time
 * (open, append, flush, close, measured around each call) and the MB written in its summary; this
 * program parses that summary, checks the file (vafm_h5_check, curve count) and takes the median of
 * S_REPS repetitions of each number. One more configuration per speed flushes after every curve
 * (--flush-interval 0) at 1 thread, for the cost that flushing by time avoids. The same curves without a
 * file (`vafm curves`, same N, speed and threads) give the reference: the slow-down a file causes, and
 * the speed-up the machine allows at all (on a shared machine the 2-thread numbers move with its load).
 *
 * Speeds: v = v~ R eta from the preset (R = 16 nm, eta = 4e5 /s). N per speed is chosen so that one
 * repetition at 1 thread takes 1.5-2.5 s on a 2020s core (a curve at v~ = 1e-3 takes ~0.1 s; its sample
 * count, and so its bytes, scale as 1/v~), and that 2 threads get at least 12 curves each (the last
 * curves of a run leave a core idle).
 * Targets (reported, not enforced): writer < 5% of the wall time; 2 threads >= 1.8x one.
 *
 * Usage: bench_campaign OUTDIR PATH/TO/vafm   writes OUTDIR/bench_campaign.csv and .md, prints the
 * markdown to stdout; the scratch file OUTDIR/bench_campaign.h5 is removed at the end.
 */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "bench_util.h"
#include "h5/h5.h"
#include "vafm/params.h"

#define S_REPS 3
#define S_NSPEED 3
#define S_WRITER_TARGET_PCT 5.0
#define S_SPEEDUP_TARGET 1.8

static const double s_vred[S_NSPEED] = { 1e-3, 1e-2, 1e-1 };
static const unsigned s_curves[S_NSPEED] = { 24, 160, 800 };

typedef struct s_run {
    double wall_s, curves_per_s, mb, mb_per_s, writer_pct;
} s_run;

typedef struct s_row {
    double vred, v;
    int threads;
    double flush_s;
    unsigned n;
    s_run med;    /* vafm campaign */
    s_run nofile; /* vafm curves: the same curves without a file (wall_s, curves_per_s only) */
    int ok;       /* every repetition ran and wrote a conforming file of n curves */
} s_row;

/* Run argv, its stdout into buf. @return the exit status, or -1. */
static int s_spawn(char *const argv[], char *buf, size_t len)
{
    int fd[2];
    if (pipe(fd))
        return -1;
    pid_t pid = fork();
    if (pid < 0) {
        close(fd[0]);
        close(fd[1]);
        return -1;
    }
    if (pid == 0) {
        dup2(fd[1], STDOUT_FILENO);
        close(fd[0]);
        close(fd[1]);
        execv(argv[0], argv);
        _exit(127);
    }
    close(fd[1]);
    size_t used = 0;
    for (;;) {
        ssize_t k = read(fd[0], buf + used, len - 1 - used);
        if (k < 0 && errno == EINTR)
            continue;
        if (k <= 0)
            break;
        used += (size_t)k;
        if (used == len - 1) {
            char sink[4096]; /* the statistics block may exceed buf: drain it */
            while (read(fd[0], sink, sizeof sink) > 0) {
            }
            break;
        }
    }
    buf[used] = '\0';
    close(fd[0]);
    int st = 0;
    if (waitpid(pid, &st, 0) < 0)
        return -1;
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

/* The numbers of the summary lines "file", "campaign" and "writer" of `vafm campaign` (nofile: only
 * the "campaign" line, which `vafm curves` prints alike). */
static int s_parse(const char *out, int nofile, s_run *r)
{
    const char *c = strstr(out, "\ncampaign "), *in = c ? strstr(c, " run in ") : NULL;
    if (!in || sscanf(in, " run in %lf s (%lf curves/s)", &r->wall_s, &r->curves_per_s) != 2)
        return -1;
    if (nofile)
        return 0;
    const char *f = strstr(out, "\nfile "), *w = strstr(out, "\nwriter ");
    const char *mb = f ? strstr(f, " new), ") : NULL;
    const char *eq = w ? strstr(w, " = ") : NULL, *mbs = w ? strstr(w, "), ") : NULL;
    if (!mb || !eq || !mbs || sscanf(mb, " new), %lf MB written", &r->mb) != 1 ||
        sscanf(eq, " = %lf%%", &r->writer_pct) != 1 || sscanf(mbs, "), %lf MB/s", &r->mb_per_s) != 1)
        return -1;
    return 0;
}

/* S_REPS runs of vafm campaign (nofile = 0) or vafm curves (1); medians into row. */
static int s_measure(const char *vafm, const char *h5, s_row *row, int nofile)
{
    char n[32], v[64], th[16], fl[32];
    snprintf(n, sizeof n, "%u", row->n);
    snprintf(v, sizeof v, "%.17g", row->v);
    snprintf(th, sizeof th, "%d", row->threads);
    snprintf(fl, sizeof fl, "%g", row->flush_s);
    char *camp[] = { (char *)vafm, "campaign", "-n", n, "--preset", "paper-fig4", "--v", v, "--threads", th,
                     "--flush-interval", fl, "--out", (char *)h5, "--overwrite", "--quiet", NULL };
    char *curves[] = { (char *)vafm, "curves", "-n", n, "--preset", "paper-fig4", "--v", v, "--threads", th,
                       "--quiet", NULL };
    static char out[1 << 16];
    double wall[S_REPS], cps[S_REPS], mb[S_REPS], mbs[S_REPS], pct[S_REPS];
    if (!nofile)
        row->ok = 1;
    for (int r = 0; r < S_REPS; r++) {
        s_run m;
        memset(&m, 0, sizeof m);
        int st = s_spawn(nofile ? curves : camp, out, sizeof out);
        if (st != 0 || s_parse(out, nofile, &m)) {
            fprintf(stderr, "bench_campaign: `vafm %s` exited %d or its summary did not parse:\n%.600s\n",
                    nofile ? "curves" : "campaign", st, out);
            return -1;
        }
        if (!nofile) {
            vafm_error e;
            memset(&e, 0, sizeof e);
            vafm_h5_reader *rd = NULL;
            if (vafm_h5_check(h5, &e) || vafm_h5_reader_open(&rd, h5, &e) || vafm_h5_reader_count(rd) != row->n) {
                fprintf(stderr, "bench_campaign: %s: %s\n", h5, e.message[0] ? e.message : "wrong curve count");
                row->ok = 0;
            }
            vafm_h5_reader_destroy(&rd);
        }
        wall[r] = m.wall_s;
        cps[r] = m.curves_per_s;
        mb[r] = m.mb;
        mbs[r] = m.mb_per_s;
        pct[r] = m.writer_pct;
    }
    s_run *dst = nofile ? &row->nofile : &row->med;
    dst->wall_s = bench_median(wall, S_REPS);
    dst->curves_per_s = bench_median(cps, S_REPS);
    dst->mb = bench_median(mb, S_REPS);
    dst->mb_per_s = bench_median(mbs, S_REPS);
    dst->writer_pct = bench_median(pct, S_REPS);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc != 3) {
        fprintf(stderr, "usage: bench_campaign OUTDIR PATH/TO/vafm\n");
        return 2;
    }
    const char *dir = argv[1], *vafm = argv[2];
    vafm_params p;
    if (vafm_preset_apply(&p, "paper-fig4", NULL)) {
        fprintf(stderr, "bench_campaign: no paper-fig4 preset\n");
        return 1;
    }
    char h5[1024], csv[1024], md[1024];
    snprintf(h5, sizeof h5, "%s/bench_campaign.h5", dir);
    snprintf(csv, sizeof csv, "%s/bench_campaign.csv", dir);
    snprintf(md, sizeof md, "%s/bench_campaign.md", dir);

    /* per speed: 1 thread, 2 threads, 1 thread flushing after every curve */
    enum { S_PER_SPEED = 3 };
    s_row rows[S_NSPEED * S_PER_SPEED];
    int nrows = 0;
    for (int i = 0; i < S_NSPEED; i++) {
        const int threads[S_PER_SPEED] = { 1, 2, 1 };
        const double flush[S_PER_SPEED] = { 1.0, 1.0, 0.0 };
        for (int j = 0; j < S_PER_SPEED; j++) {
            s_row *r = &rows[nrows++];
            memset(r, 0, sizeof *r);
            r->vred = s_vred[i];
            r->v = s_vred[i] * p.R_m * p.eta_per_s;
            r->threads = threads[j];
            r->flush_s = flush[j];
            r->n = s_curves[i];
            fprintf(stderr, "bench_campaign: v~ = %g (v = %g m/s), %d thread(s), flush every %g s, %u curves x %d\n",
                    r->vred, r->v, r->threads, r->flush_s, r->n, S_REPS);
            if (s_measure(vafm, h5, r, 0))
                return 1;
            if (j < 2 && s_measure(vafm, h5, r, 1))
                return 1;
            if (j == 2)
                r->nofile = rows[nrows - 3].nofile; /* same curves, same threads as the first row */
        }
    }
    remove(h5);

    FILE *fc = fopen(csv, "w"), *fm = fopen(md, "w");
    if (!fc || !fm) {
        fprintf(stderr, "bench_campaign: cannot write %s or %s\n", csv, md);
        return 1;
    }
    fprintf(fc, "v_reduced,v_m_per_s,threads,flush_interval_s,curves,reps,wall_s,curves_per_s,MB,MB_per_s,"
                "writer_share_pct,speedup_vs_1_thread,nofile_wall_s,nofile_curves_per_s,slowdown_vs_nofile_pct,"
                "nofile_speedup_vs_1_thread,file_ok\n");
    for (int i = 0; i < nrows; i++) {
        const s_row *r = &rows[i], *one = &rows[(i / S_PER_SPEED) * S_PER_SPEED];
        fprintf(fc, "%g,%.6g,%d,%g,%u,%d,%.4f,%.4f,%.4f,%.4f,%.3f,%.4f,%.4f,%.4f,%.3f,%.4f,%d\n", r->vred, r->v,
                r->threads, r->flush_s, r->n, S_REPS, r->med.wall_s, r->med.curves_per_s, r->med.mb, r->med.mb_per_s,
                r->med.writer_pct, r->med.curves_per_s / one->med.curves_per_s, r->nofile.wall_s,
                r->nofile.curves_per_s, 100.0 * (r->nofile.curves_per_s / r->med.curves_per_s - 1.0),
                r->nofile.curves_per_s / one->nofile.curves_per_s, r->ok);
    }
    long ncpu = sysconf(_SC_NPROCESSORS_ONLN);
    double load[3] = { 0, 0, 0 };
    FILE *la = fopen("/proc/loadavg", "r");
    if (la) {
        if (fscanf(la, "%lf %lf %lf", &load[0], &load[1], &load[2]) != 3)
            load[0] = load[1] = load[2] = 0;
        fclose(la);
    }
    FILE *outs[2] = { fm, stdout };
    for (int k = 0; k < 2; k++) {
        FILE *o = outs[k];
        fprintf(o, "## Campaign throughput: `vafm campaign`, paper-fig4, one HDF5 file\n\n");
        fprintf(o, "Median of %d runs each; %ld online CPUs, load average %.2f at the end. Writer share = time "
                   "in open, append, flush and close / wall time. Slow-down = how much longer the same curves "
                   "take with the file than without (`vafm curves`, same threads). Flush every 1 s unless "
                   "marked \"every curve\". Targets (reported, not enforced): writer < %.0f%% of the wall; "
                   "2 threads >= %.1fx one.\n\n",
                S_REPS, ncpu, load[0], S_WRITER_TARGET_PCT, S_SPEEDUP_TARGET);
        fprintf(o, "| v~ | v (m/s) | threads | flush | curves | wall (s) | curves/s | MB/s | writer share | "
                   "slow-down vs no file | speed-up vs 1 thread | (no file) | file |\n");
        fprintf(o, "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
        for (int i = 0; i < nrows; i++) {
            const s_row *r = &rows[i], *one = &rows[(i / S_PER_SPEED) * S_PER_SPEED];
            double su = r->med.curves_per_s / one->med.curves_per_s;
            double su0 = r->nofile.curves_per_s / one->nofile.curves_per_s;
            char sus[48];
            if (r->threads == 2)
                snprintf(sus, sizeof sus, "%.2fx (%s)", su, su >= S_SPEEDUP_TARGET ? "met" : "missed");
            else
                snprintf(sus, sizeof sus, "%.2fx", su);
            fprintf(o, "| %g | %.3g | %d | %s | %u | %.3f | %.4g | %.3g | %.2f%% (%s) | %+.1f%% | %s | %.2fx | %s |\n",
                    r->vred, r->v, r->threads, r->flush_s > 0 ? "1 s" : "every curve", r->n, r->med.wall_s,
                    r->med.curves_per_s, r->med.mb_per_s, r->med.writer_pct,
                    r->med.writer_pct < S_WRITER_TARGET_PCT ? "met" : "missed",
                    100.0 * (r->nofile.curves_per_s / r->med.curves_per_s - 1.0), sus, su0,
                    r->ok ? "conforms" : "BAD");
        }
        fprintf(o, "\n");
    }
    int bad = fclose(fc) != 0;
    bad |= fclose(fm) != 0;
    return bad;
}
