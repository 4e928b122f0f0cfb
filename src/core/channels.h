/* SPDX-License-Identifier: MIT */
/*
 * The one list of the output channels (an X-macro, header only, as models.h): what each per-sample signal
 * is called on the wire, in which unit, under which dataset name it goes into a file (afmformats' names,
 * protocol/hdf5.md), whether it is what the instrument measures or the simulation's truth, its dtype, and
 * where it sits in the samples CSV (protocol/csv.md). Everything that names or counts channels is derived
 * from these rows: the stream's channel bits and arrays (vafmd: bit i = row i), the channel list of
 * `hello` and `run.start` (run_json.c), the replay's channels (replay.c), `vafm listen`'s columns
 * (cli/ctl_listen.c), the CSV headers of `vafm samples` and `vafm export`, the MPI campaign's packed curve
 * and the Python client's CHANNELS (tests/test_channels.py parses this file and compares).
 *
 *   X(ID, "stream name", "unit", "file dataset" | NULL, kind, flags, csv, field)
 *     ID       VAFM_CH_<ID> is the row's index and its bit in a run's channel mask (streamed rows first)
 *     kind     VAFM_CHK_MEASURED (the detector chain's output: what an instrument records),
 *              VAFM_CHK_TRUTH (the simulation's, never seen by an instrument), VAFM_CHK_CLOCK (time base),
 *              VAFM_CHK_SEGMENT (the sample's segment, vafm_samples.segment, as a double)
 *     flags    VAFM_CHF_LIVE: every live run streams it; VAFM_CHF_REPLAY: only replays stream it (a file's
 *              time column); VAFM_CHF_OPTIONAL: a live run streams it when the scene has it (the measured
 *              height of a piezo model or a z sensor); VAFM_CHF_OPTIN: a live run streams it when the
 *              client asked for it (vafmd's setting segment_channel)
 *     csv      its column in the samples CSV, from 1 (0: not a column of it)
 *     field    its array in vafm_samples (sim.h); `n` for none (the detector's volts: the daemon
 *              computes them, vafm_channel_samples returns NULL)
 *
 * The order of the streamed rows is the wire's (protocol/wire.md §3.2) and must not change; a new channel
 * is appended (docs/architecture.md, "Recipe: a new output channel"). The segment is a column of files and
 * CSVs (VAFM_CH_SEGMENT_FILE, _CSV: a uint8 array, not a row); on the stream it is the opt-in row SEGMENT (the
 * block header holds only a block's first segment, the events the changes).
 */
#ifndef VAFM_CORE_CHANNELS_H
#define VAFM_CORE_CHANNELS_H

#include <stddef.h>
#include <stdio.h>
#include <string.h>
#include "vafm/sim.h"

enum { VAFM_CHK_MEASURED, VAFM_CHK_TRUTH, VAFM_CHK_CLOCK, VAFM_CHK_SEGMENT };
enum { VAFM_CHF_LIVE = 1, VAFM_CHF_REPLAY = 2, VAFM_CHF_OPTIONAL = 4, VAFM_CHF_OPTIN = 8 };

/* A test build may append rows (tests/test_channels.py builds one with a dummy channel). */
#ifndef VAFM_CHANNELS_EXTRA
#define VAFM_CHANNELS_EXTRA(X)
#endif

/* clang-format off */
#define VAFM_CHANNELS(X)                                                                                    \
    X(HEIGHT,          "height_m",          "m", "height (piezo)",    VAFM_CHK_TRUTH,    VAFM_CHF_LIVE,     2, height_m)          \
    X(DEFLECTION,      "deflection_m",      "m", NULL,                VAFM_CHK_MEASURED, VAFM_CHF_LIVE,     3, deflection_m)      \
    X(FORCE,           "force_N",           "N", "force",             VAFM_CHK_MEASURED, VAFM_CHF_LIVE,     4, force_N)           \
    X(VDEFLECTION,     "vDeflection_V",     "V", NULL,                VAFM_CHK_MEASURED, VAFM_CHF_LIVE,     0, n)                 \
    X(TIP,             "tip_m",             "m", "tip position",      VAFM_CHK_TRUTH,    VAFM_CHF_LIVE,     5, tip_m)             \
    X(TIME,            "time_s",            "s", "time",              VAFM_CHK_CLOCK,    VAFM_CHF_REPLAY,   1, time_s)            \
    X(HEIGHT_MEASURED, "height_measured_m", "m", "height (measured)", VAFM_CHK_MEASURED, VAFM_CHF_OPTIONAL, 7, height_measured_m) \
    X(SEGMENT,         "segment",           "",  NULL,                VAFM_CHK_SEGMENT,  VAFM_CHF_OPTIN,    0, n)                 \
    VAFM_CHANNELS_EXTRA(X)
/* clang-format on */

#define VAFM_CH_ENUM_(ID, name, unit, file, kind, flags, csv, field) VAFM_CH_##ID,
/** VAFM_CH_HEIGHT … : a channel's row, and its bit in a run's channel mask. */
enum vafm_channel_id { VAFM_CHANNELS(VAFM_CH_ENUM_) VAFM_CH_COUNT };
#undef VAFM_CH_ENUM_

/** The segment column (uint8, enum vafm_segment): in files and CSVs, not a channel of the stream. */
#define VAFM_CH_SEGMENT_FILE "segment"
#define VAFM_CH_SEGMENT_CSV 6

typedef struct vafm_channel {
    const char *name;  /* on the wire, in the CSV header and in the Python client */
    const char *unit;  /* SI */
    const char *file;  /* dataset of a curve group (protocol/hdf5.md), NULL: not in files */
    int kind;          /* VAFM_CHK_* */
    int flags;         /* VAFM_CHF_* */
    int csv;           /* column of the samples CSV from 1, 0: none */
    ptrdiff_t field;   /* offset of its array in vafm_samples, -1: none (the detector's volts) */
} vafm_channel;

/* field n (offset 0: no array starts there) marks a channel that is not a vafm_samples array */
#define VAFM_CH_ROW_(ID, name, unit, file, kind, flags, csv, field)                                     \
    { name, unit, file, kind, flags, csv,                                                               \
      offsetof(vafm_samples, field) == 0 ? (ptrdiff_t)-1 : (ptrdiff_t)offsetof(vafm_samples, field) },
static const vafm_channel vafm_channels[VAFM_CH_COUNT] = { VAFM_CHANNELS(VAFM_CH_ROW_) };
#undef VAFM_CH_ROW_

/** Dtype of every streamed channel (little-endian float64). */
#define VAFM_CH_DTYPE "<f8"

/** The channel bits of the rows with any of these flags (VAFM_CHF_LIVE: what every live run streams). */
static inline unsigned vafm_channels_mask(int flags)
{
    unsigned m = 0;
    for (int i = 0; i < VAFM_CH_COUNT; i++)
        if (vafm_channels[i].flags & flags)
            m |= 1u << i;
    return m;
}

/** The row of a stream name, -1: none. */
static inline int vafm_channel_find(const char *name)
{
    for (int i = 0; i < VAFM_CH_COUNT; i++)
        if (!strcmp(vafm_channels[i].name, name))
            return i;
    return -1;
}

/** Channel i's array in a block of samples, NULL: the block has none (or it is not a vafm_samples field). */
static inline const double *vafm_channel_samples(const vafm_samples *b, int i)
{
    if (vafm_channels[i].field < 0)
        return NULL;
    const double *p;
    memcpy(&p, (const char *)b + vafm_channels[i].field, sizeof p);
    return p;
}

/** Set channel i's array of a block (no-op for a channel that is not a vafm_samples field). */
static inline void vafm_channel_set_samples(vafm_samples *b, int i, const double *p)
{
    if (vafm_channels[i].field >= 0)
        memcpy((char *)b + vafm_channels[i].field, &p, sizeof p);
}

/** Rows that go into a file (a dataset of protocol/hdf5.md): what vafmd's log keeps of a run. */
static inline int vafm_channels_filed(void)
{
    int k = 0;
    for (int i = 0; i < VAFM_CH_COUNT; i++)
        k += vafm_channels[i].file != NULL;
    return k;
}

/** Samples [i, i + m) of a block: every channel's array (and the segments) advanced by i. */
static inline vafm_samples vafm_channels_slice(const vafm_samples *b, size_t i, size_t m)
{
    vafm_samples s = *b;
    s.n = m;
    s.first = b->first + i;
    for (int c = 0; c < VAFM_CH_COUNT; c++) {
        const double *p = vafm_channel_samples(b, c);
        vafm_channel_set_samples(&s, c, p ? p + i : NULL);
    }
    s.segment = b->segment ? b->segment + i : NULL;
    return s;
}

/** The row at CSV column c (1 … ), -1: none there (the segment's column, or past the last). */
static inline int vafm_channel_at_csv(int c)
{
    for (int i = 0; i < VAFM_CH_COUNT; i++)
        if (vafm_channels[i].csv == c)
            return i;
    return -1;
}

/** The samples CSV's header cells of columns 1 … last, comma-separated, no newline (protocol/csv.md).
 *  @return 0, or -1 if writing failed. */
static inline int vafm_channels_csv_head(FILE *f, int last)
{
    for (int c = 1; c <= last; c++) {
        int i = vafm_channel_at_csv(c);
        const char *name = c == VAFM_CH_SEGMENT_CSV ? VAFM_CH_SEGMENT_FILE : i >= 0 ? vafm_channels[i].name : "";
        if (fprintf(f, "%s%s", c > 1 ? "," : "", name) < 0)
            return -1;
    }
    return 0;
}

#endif
