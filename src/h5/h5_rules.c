/* SPDX-License-Identifier: MIT */
/*
 * The value rules shared by the HDF5 writer, reader and checker (protocol/hdf5.md L- and V-rules): date and
 * time strings, a JSON object's syntax, curve group names and sorted curve numbers, the segment labels and
 * lists, and the time and tip-position columns. Each rule returns NULL (or 1) when a value keeps it, else the
 * rule's wording and where it broke.
 */
#include <ctype.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "h5/h5_internal.h"

/* ---- value rules ---------------------------------------------------------------------------------- */

static int s_digits(const char *s, int n)
{
    for (int i = 0; i < n; i++)
        if (!isdigit((unsigned char)s[i]))
            return 0;
    return 1;
}

int vafm_h5i_date_ok(const char *s)
{
    if (!s || strlen(s) != 10 || !s_digits(s, 4) || s[4] != '-' || !s_digits(s + 5, 2) || s[7] != '-' ||
        !s_digits(s + 8, 2))
        return 0;
    int mo = (s[5] - '0') * 10 + (s[6] - '0'), d = (s[8] - '0') * 10 + (s[9] - '0');
    return mo >= 1 && mo <= 12 && d >= 1 && d <= 31;
}

int vafm_h5i_time_ok(const char *s)
{
    if (!s || strlen(s) < 8 || !s_digits(s, 2) || s[2] != ':' || !s_digits(s + 3, 2) || s[5] != ':' ||
        !s_digits(s + 6, 2))
        return 0;
    int h = (s[0] - '0') * 10 + (s[1] - '0'), m = (s[3] - '0') * 10 + (s[4] - '0'),
        sec = (s[6] - '0') * 10 + (s[7] - '0');
    if (h > 23 || m > 59 || sec > 60)
        return 0;
    if (!s[8])
        return 1;
    if (s[8] != '.' || !s[9])
        return 0;
    for (const char *p = s + 9; *p; p++)
        if (!isdigit((unsigned char)*p))
            return 0;
    return 1;
}

/* A small recursive-descent JSON syntax check (RFC 8259), depth-limited. */
static const char *s_json_value(const char *p, int depth);

static const char *s_ws(const char *p)
{
    while (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r')
        p++;
    return p;
}

static const char *s_json_string(const char *p)
{
    if (*p != '"')
        return NULL;
    for (p++; *p && *p != '"'; p++) {
        if ((unsigned char)*p < 0x20)
            return NULL;
        if (*p == '\\') {
            p++;
            if (*p == 'u') {
                for (int i = 1; i <= 4; i++)
                    if (!isxdigit((unsigned char)p[i]))
                        return NULL;
                p += 4;
            } else if (!*p || !strchr("\"\\/bfnrt", *p)) {
                return NULL;
            }
        }
    }
    return *p == '"' ? p + 1 : NULL;
}

static const char *s_json_number(const char *p)
{
    if (*p == '-')
        p++;
    if (*p == '0')
        p++;
    else if (isdigit((unsigned char)*p))
        while (isdigit((unsigned char)*p))
            p++;
    else
        return NULL;
    if (*p == '.') {
        p++;
        if (!isdigit((unsigned char)*p))
            return NULL;
        while (isdigit((unsigned char)*p))
            p++;
    }
    if (*p == 'e' || *p == 'E') {
        p++;
        if (*p == '+' || *p == '-')
            p++;
        if (!isdigit((unsigned char)*p))
            return NULL;
        while (isdigit((unsigned char)*p))
            p++;
    }
    return p;
}

static const char *s_json_value(const char *p, int depth)
{
    if (depth > 64)
        return NULL;
    p = s_ws(p);
    if (*p == '{' || *p == '[') {
        char close = *p == '{' ? '}' : ']';
        int obj = *p == '{';
        p = s_ws(p + 1);
        if (*p == close)
            return p + 1;
        for (;;) {
            if (obj) {
                p = s_json_string(s_ws(p));
                if (!p)
                    return NULL;
                p = s_ws(p);
                if (*p != ':')
                    return NULL;
                p++;
            }
            p = s_json_value(p, depth + 1);
            if (!p)
                return NULL;
            p = s_ws(p);
            if (*p == ',') {
                p++;
                continue;
            }
            return *p == close ? p + 1 : NULL;
        }
    }
    if (*p == '"')
        return s_json_string(p);
    if (!strncmp(p, "true", 4))
        return p + 4;
    if (!strncmp(p, "false", 5))
        return p + 5;
    if (!strncmp(p, "null", 4))
        return p + 4;
    return s_json_number(p);
}

int vafm_h5i_json_object_ok(const char *s)
{
    if (!s)
        return 0;
    const char *p = s_ws(s);
    if (*p != '{')
        return 0;
    p = s_json_value(p, 0);
    return p && !*s_ws(p);
}

int vafm_h5i_group_name(const char *name, uint64_t *out)
{
    size_t n = strlen(name);
    if (n == 0 || n > 19 || !s_digits(name, (int)n) || (n > 1 && name[0] == '0'))
        return 0;
    uint64_t v = strtoull(name, NULL, 10);
    if (v > (uint64_t)INT64_MAX)
        return 0;
    *out = v;
    return 1;
}

int vafm_h5i_u64_cmp(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : x > y;
}

size_t vafm_h5i_u64_lower_bound(const uint64_t *v, size_t n, uint64_t key)
{
    size_t lo = 0, hi = n;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (v[mid] < key)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

const char *vafm_h5i_rule_segment(const uint8_t *seg, size_t n, int64_t count, int list, size_t *at)
{
    /* L12: a force-distance curve (count absent or 2) labels 0 approach, 1 retract, 2 dwell; a curve of
     * another count (a segment list: afmformats' multi-segment convention) labels each sample with its
     * segment's position in the list, 0..count−1 */
    int two = !list && (count < 0 || count == 2);
    unsigned lim = two ? 3u : count > 256 ? 256u : (unsigned)count;
    for (size_t i = 0; i < n; i++)
        if (seg[i] >= lim) {
            *at = i;
            return two ? "segment values are 0 (approach), 1 (retract) or 2 (dwell)"
                       : "segment values are below 'segment count' (a segment list: the segment's position)";
        }
    return NULL;
}

int vafm_h5i_segments_count(const char *s)
{
    /* {"segments": [{...}, ...]}: the one key, an array of 1..VAFM_H5_SEGMENTS_MAX objects, nothing after */
    if (!s || !vafm_h5i_json_object_ok(s))
        return -1;
    const char *p = s_ws(s_ws(s) + 1);
    if (strncmp(p, "\"segments\"", 10))
        return -1;
    p = s_ws(p + 10);
    if (*p != ':')
        return -1;
    p = s_ws(p + 1);
    if (*p != '[')
        return -1;
    p = s_ws(p + 1);
    int n = 0;
    while (*p == '{') {
        if (++n > VAFM_H5_SEGMENTS_MAX || !(p = s_json_value(p, 1)))
            return -1;
        p = s_ws(p);
        if (*p == ',')
            p = s_ws(p + 1);
        else
            break;
    }
    if (n < 1 || *p != ']')
        return -1;
    p = s_ws(p + 1);
    return *p == '}' && !*s_ws(p + 1) ? n : -1;
}

const char *vafm_h5i_rule_finite(const double *x, size_t n, size_t *at)
{
    for (size_t i = 0; i < n; i++)
        if (!isfinite(x[i])) {
            *at = i;
            return "values are finite numbers";
        }
    return NULL;
}

const char *vafm_h5i_rule_time(const double *t, size_t n, size_t *at)
{
    const char *r = vafm_h5i_rule_finite(t, n, at);
    if (r)
        return r;
    if (n == 0)
        return NULL;
    if (t[0] < 0) {
        *at = 0;
        return "time starts at 0 (the first sample lies within one sample interval of 0)";
    }
    for (size_t i = 1; i < n; i++)
        if (!(t[i] > t[i - 1])) {
            *at = i;
            return "time increases strictly from sample to sample";
        }
    /* "continuous from 0": the first sample lies within one sample interval of 0 (vafm stamps a box-car
     * averaged sample at the middle of its interval, so t[0] = interval/2). The interval is the mean one, or
     * the first one where that is longer: a segment list may record its first segment at a lower rate than
     * the rest (t[0] = d/(2 fs), t[1] − t[0] ≥ d/(2 fs) whatever the next segment's rate). */
    double mean = n >= 2 ? (t[n - 1] - t[0]) / (double)(n - 1) : 0, first = n >= 2 ? t[1] - t[0] : 0;
    if (n >= 2 && t[0] > (first > mean ? first : mean) * (1 + 1e-9)) {
        *at = 0;
        return "time starts at 0 (the first sample lies within one sample interval of 0)";
    }
    return NULL;
}

const char *vafm_h5i_rule_tip(const double *tip, const double *hm, const double *f, double k, size_t n,
                              size_t *at)
{
    if (!(k > 0) || !isfinite(k)) {
        *at = 0;
        return "tip position needs a positive spring constant (tip position = height (measured) + "
               "force / spring constant)";
    }
    for (size_t i = 0; i < n; i++) {
        double want = hm[i] + f[i] / k;
        /* equal up to rounding: the writer's source may form h + deflection instead of h + F/k */
        double tol = 1e-9 * (fabs(hm[i]) + fabs(f[i] / k)) + 1e-300;
        if (!(fabs(tip[i] - want) <= tol)) {
            *at = i;
            return "tip position = height (measured) + force / spring constant (nanite's tip-sample "
                   "separation)";
        }
    }
    return NULL;
}
