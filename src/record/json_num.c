/* SPDX-License-Identifier: MIT */
/* Number literals of JSON text that underflow (record/json_num.h). */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "record/json_num.h"

void vafm_rec_json_key_before(const char *b, size_t pos, int enclosing, char *key, size_t len)
{
    key[0] = '\0';
    size_t i = pos;
    while (i > 0 && b[i - 1] != ':' && (enclosing || (b[i - 1] != ',' && b[i - 1] != '[' && b[i - 1] != '{')))
        i--;
    if (i == 0 || b[i - 1] != ':')
        return;
    size_t end = i - 1;
    while (end > 0 && strchr(" \t\r\n", b[end - 1]))
        end--;
    if (end == 0 || b[end - 1] != '"')
        return;
    size_t start = end - 1;
    while (start > 0 && b[start - 1] != '"')
        start--;
    size_t k = end - 1 - start;
    if (start == 0 || k == 0 || k >= len)
        return;
    for (size_t j = 0; j < k; j++)
        if ((unsigned char)b[start + j] < 0x20 || b[start + j] == '\\')
            return;
    memcpy(key, b + start, k);
    key[k] = '\0';
}

int vafm_rec_json_underflow(const char *b, size_t n, int enclosing, char *key, size_t keylen, char *lit, size_t litlen,
                            size_t *line, double *as)
{
    int in_str = 0;
    size_t ln = 1;
    for (size_t i = 0; i < n && b[i]; i++) {
        char ch = b[i];
        if (ch == '\n')
            ln++;
        if (in_str) {
            if (ch == '\\' && i + 1 < n)
                i++;
            else if (ch == '"')
                in_str = 0;
            continue;
        }
        if (ch == '"') {
            in_str = 1;
            continue;
        }
        if (ch != '-' && (ch < '0' || ch > '9'))
            continue; /* outside strings only numbers hold '-' and digits */
        size_t j = i;
        int nonzero = 0, in_exp = 0;
        for (; j < n && b[j] && strchr("+-.0123456789eE", b[j]); j++) {
            in_exp |= b[j] == 'e' || b[j] == 'E';
            nonzero |= !in_exp && b[j] >= '1' && b[j] <= '9';
        }
        if (nonzero) {
            char t[128];
            /* a literal longer than t: its digits decide, so read it whole (bounded by the text, n) */
            char *s = j - i < sizeof t ? t : malloc(j - i + 1);
            double x = 1.0;
            if (s) {
                memcpy(s, b + i, j - i);
                s[j - i] = '\0';
                x = strtod(s, NULL);
            }
            if (s && fabs(x) < DBL_MIN) {
                if (keylen)
                    vafm_rec_json_key_before(b, i, enclosing, key, keylen);
                if (litlen) {
                    size_t l = strlen(s) < litlen ? strlen(s) : litlen - 1;
                    memcpy(lit, s, l);
                    lit[l] = '\0';
                }
                *line = ln;
                *as = x;
                if (s != t)
                    free(s);
                return 1;
            }
            if (s != t)
                free(s);
        }
        i = j - 1;
    }
    return 0;
}
