/* SPDX-License-Identifier: MIT */
/*
 * Fuzz driver for the vafmd command decoder (src/daemon/cmd_json.c).
 *
 * Built with -DVAFMD_LIBFUZZER it is a libFuzzer target (LLVMFuzzerTestOneInput). Otherwise main() runs
 * a corpus of valid and invalid requests, then a bounded number of random mutations of them (byte
 * flips, insertions, deletions, truncations, splices; fixed seed so a failure reproduces). Each input
 * must decode or yield an error with a known code and a message, and whatever decodes is executed
 * against a scratch scene (set/get) without crashing. ASan/UBSan do the rest.
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "daemon/cmd_json.h"
#include "daemon/faults.h"
#include "vafm/wire.h"
#include "harness.h"

static const char *const s_codes[] = { VAFMD_E_MALFORMED, VAFMD_E_TOO_LARGE, VAFMD_E_UNKNOWN_COMMAND,
                                       VAFMD_E_UNKNOWN_FIELD, VAFMD_E_MISSING_FIELD, VAFMD_E_WRONG_TYPE,
                                       VAFMD_E_OUT_OF_RANGE, VAFMD_E_NOT_FOUND, VAFMD_E_INVALID_SCENE,
                                       VAFMD_E_READ_ONLY };

static int s_known_code(const char *c)
{
    for (size_t i = 0; i < sizeof s_codes / sizeof *s_codes; i++)
        if (c && !strcmp(c, s_codes[i]))
            return 1;
    return 0;
}

/* @return 1 if the input decoded, 0 if it was rejected; -1 on a broken invariant. */
static int s_one(const uint8_t *data, size_t len)
{
    vafmd_cmd c;
    vafmd_err e = { 0 };
    int ok = vafmd_cmd_decode(data, len, &c, &e) == 0;
    if (ok) {
        vafm_params p;
        vafmd_settings s;
        vafm_params_default(&p);
        vafmd_settings_default(&s);
        if (c.kind == VAFMD_CMD_SET) {
            vafm_params p0 = p;
            if (vafmd_apply_set(&p, &s, &c, &e)) {
                if (!s_known_code(e.code) || memcmp(&p, &p0, sizeof p))
                    ok = -1; /* a failed set must change nothing */
            }
        } else if (c.kind == VAFMD_CMD_GET) {
            json_t *v = vafmd_get_values(&p, &s, &c, &e);
            if (!v && !s_known_code(e.code))
                ok = -1;
            json_decref(v);
        } else if (c.kind == VAFMD_CMD_FAULTS && c.fault_plan) {
            /* a fault plan: accepted, or refused with a known code, a field and a message */
            static vafmd_fault_plan fp;
            vafmd_err fe = { 0 };
            if (vafmd_faults_decode(c.fault_plan, &fp, &fe) && (!s_known_code(fe.code) || !fe.message[0]))
                ok = -1;
        } else if (c.kind == VAFMD_CMD_LOG) {
            /* a decoded log is a stop alone, or a start with a path of a bounded length and not both flags */
            if (c.log_stop ? (c.log_path || c.log_overwrite || c.log_resume)
                           : (!c.log_path || !c.log_path[0] || strlen(c.log_path) > VAFMD_LOG_PATH_MAX ||
                              (c.log_overwrite && c.log_resume)))
                ok = -1;
        }
    } else if (!s_known_code(e.code) || !e.message[0]) {
        ok = -1;
    }
    vafmd_cmd_free(&c); /* a rejected request is kept too (its id is echoed) */
    if (!ok) {
        json_t *r = vafmd_error_reply(&e, NULL);
        char *t = json_dumps(r, JSON_COMPACT);
        if (!t || !strstr(t, "\"status\":\"error\""))
            ok = -1;
        free(t);
        json_decref(r);
    }
    return ok;
}

#ifdef VAFMD_LIBFUZZER
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (s_one(data, size) < 0)
        abort();
    return 0;
}
#else
static const char *const s_corpus[] = {
    "{\"cmd\":\"hello\"}",
    "{\"cmd\":\"faults\",\"plan\":{\"seed\":3,\"script\":[{\"kind\":\"drop\",\"run\":2,\"block\":5,\"blocks\":3},"
    "{\"kind\":\"no_reply\",\"cmd\":\"curve\",\"nth\":2},{\"kind\":\"dropout\",\"time_s\":0.1,\"value\":\"stuck\"}],"
    "\"random\":{\"late\":{\"per_block\":0.1,\"delay_s\":0.2},\"busy\":{\"per_command\":0.5,\"cmd\":\"get\"}}}}",
    "{\"cmd\":\"faults\",\"clear\":true}",
    "{\"cmd\":\"hello\",\"id\":42}",
    "{\"cmd\":\"get\"}",
    "{\"cmd\":\"get\",\"names\":[\"k_N_per_m\",\"speed\"],\"info\":true}",
    "{\"cmd\":\"get\",\"names\":[\"nope\"]}",
    "{\"cmd\":\"set\",\"values\":{\"k_N_per_m\":0.1,\"T_K\":300}}",
    "{\"cmd\":\"set\",\"values\":{\"k_N_per_m\":1e99}}",
    "{\"cmd\":\"set\",\"values\":{\"k_N_per_m\":\"0.1\"}}",
    "{\"cmd\":\"set\",\"values\":{\"integrator\":\"baoab\",\"seed\":\"18446744073709551615\"}}",
    "{\"cmd\":\"set\",\"values\":{\"seed\":-1,\"free_exact\":true}}",
    "{\"cmd\":\"set\",\"preset\":\"paper-fig4\",\"values\":{\"speed\":2,\"free_run\":true,\"block_s\":0.002}}",
    "{\"cmd\":\"set\",\"preset\":\"nope\"}",
    "{\"cmd\":\"set\",\"values\":{\"hwm\":5}}",
    "{\"cmd\":\"set\",\"values\":{\"lookahead_s\":0.5}}",
    "{\"cmd\":\"set\",\"values\":{\"lookahead_s\":-1,\"speed\":0}}",
    "{\"cmd\":\"set\",\"values\":{\"dt_s\":1}}",
    "{\"cmd\":\"presets\"}",
    "{\"cmd\":\"curve\",\"index\":3,\"client_run_id\":\"abc\"}",
    "{\"cmd\":\"curve\",\"index\":-3}",
    "{\"cmd\":\"tune\",\"duration_s\":0.5}",
    "{\"cmd\":\"tune\",\"duration_s\":\"x\"}",
    "{\"cmd\":\"abort\"}",
    "{\"cmd\":\"status\"}",
    "{\"cmd\":\"shutdown\"}",
    "{\"cmd\":\"campaign\",\"anything\":[1,2]}",
    "{\"cmd\":\"campaign\",\"n\":3,\"T_K\":[300,350],\"v_m_per_s\":[1e-6],\"k_N_per_m\":[0.1,0.2],\"first_index\":2,"
    "\"client_run_id\":\"c1\"}",
    "{\"cmd\":\"campaign\",\"n\":1e9,\"T_K\":[],\"first_index\":-1}",
    "{\"cmd\":\"campaign\",\"n\":2,\"k_N_per_m\":[\"x\",null]}",
    "{\"cmd\":\"set\",\"values\":{\"noise_V_rms\":0.01,\"adc_bits\":16,\"adc_range_V\":20,\"baseline_offset_V\":-1}}",
    "{\"cmd\":\"set\",\"values\":{\"adc_bits\":3.5,\"adc_range_V\":0}}",
    "{\"cmd\":\"replay\",\"path\":\"run.h5\",\"curves\":\"2,0-1\",\"speed\":10,\"loop\":3,\"client_run_id\":\"r\"}",
    "{\"cmd\":\"replay\",\"path\":\"run.h5\",\"curves\":[0,5,-1],\"loop\":0}",
    "{\"cmd\":\"replay\",\"path\":\"\",\"curves\":\"5-2,x\",\"speed\":-1,\"loop\":1.5}",
    "{\"cmd\":\"replay\",\"curves\":{}}",
    "{\"cmd\":\"engage\",\"at_s\":1.5}",
    "{\"cmd\":\"withdraw\",\"motor_steps\":3,\"at_s\":-1}",
    "{\"cmd\":\"move\",\"x_m\":1e-6,\"y_m\":-2e-6,\"speed_m_per_s\":1e-5}",
    "{\"cmd\":\"z\",\"z_m\":\"x\"}",
    "{\"cmd\":\"feedback\",\"on\":true,\"setpoint\":2e-9,\"unit\":\"V\",\"relative\":false,\"tau_s\":0.001}",
    "{\"cmd\":\"log\",\"path\":\"/tmp/x.h5\"}",
    "{\"cmd\":\"log\",\"path\":\"a.h5\",\"overwrite\":true}",
    "{\"cmd\":\"log\",\"path\":\"a.h5\",\"resume\":true,\"overwrite\":true}",
    "{\"cmd\":\"log\",\"stop\":true}",
    "{\"cmd\":\"log\",\"stop\":1,\"path\":\"\"}",
    "{\"cmd\":\"log\",\"path\":\"x\\u0000y.h5\"}",
    "{\"cmd\":\"bogus\"}",
    "{\"cmd\":7}",
    "{\"cmd\":\"hello\",\"cmd\":\"hello\"}",
    "{\"cmd\":\"hello\",\"extra\":1}",
    "[1,2,3]",
    "\"hello\"",
    "{\"cmd\":\"he\\u0000llo\"}",
    "{\"cmd\":\"set\",\"values\":{\"contact\":\"jkr\\u0000x\"}}",
    "{\"cmd\":\"set\",\"preset\":\"paper-fig4\\u0000x\"}",
    "{",
    "",
    "{\"cmd\":\"curve\",\"client_run_id\":\"\"}",
    "{\"cmd\":\"get\",\"names\":[1]}",
    "{\"cmd\":\"set\",\"values\":[]}",
    "{\"cmd\":\"set\",\"values\":{\"\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9"
    "\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9"
    "\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\\u00e9\":1}}",
};
#define S_N_CORPUS (sizeof s_corpus / sizeof *s_corpus)

static uint64_t s_rng = 0x9E3779B97F4A7C15u;
static uint64_t s_next(void) /* xorshift64*: a fixed, portable sequence */
{
    s_rng ^= s_rng >> 12;
    s_rng ^= s_rng << 25;
    s_rng ^= s_rng >> 27;
    return s_rng * 2685821657736338717u;
}

static const char *const s_tokens[] = { "{", "}", "[", "]", ",", ":", "\"", "\\", "1e308", "-0", "null", "true",
                                        "\"k_N_per_m\"", "\"values\"", "\"cmd\"", "\"set\"", "\xff", "\xc3",
                                        "\\u0000", "\\ud800", "18446744073709551616", "NaN" };

/* The data header: byte positions of protocol/wire.md §4, independent of the host's byte order. */
static void s_wire_header(void)
{
    vafm_wire_header h = { VAFM_WIRE_MAGIC, VAFM_WIRE_PROTOCOL_VERSION, VAFM_WIRE_HEADER_SIZE, 0x0102030405060708u,
                           9, 10, 0x1112131415161718u, 1000, 5, 2, 200000.0, -5, 6, { 0 } }, g;
    unsigned char b[VAFM_WIRE_HEADER_SIZE];
    vafm_wire_header_encode(&h, b);
    ENSURE(b[0] == 'V' && b[1] == 'A' && b[2] == 'F' && b[3] == 'M');
    ENSURE(b[4] == 1 && b[5] == 0 && b[6] == 72 && b[7] == 0);
    ENSURE(b[8] == 0x08 && b[15] == 0x01);   /* seq, little-endian */
    ENSURE(b[16] == 9 && b[24] == 10 && b[32] == 0x18 && b[39] == 0x11);
    ENSURE(b[40] == 0xe8 && b[41] == 0x03 && b[44] == 5 && b[46] == 2);
    ENSURE(b[55] == 0x41 && b[56] == 0xfb && b[63] == 0xff && b[64] == 6); /* 2e5 = 0x41086A0000000000 */
    ENSURE(vafm_wire_header_decode(b, sizeof b, &g) == 0 && !memcmp(&g, &h, sizeof h));
    ENSURE(vafm_wire_header_decode(b, sizeof b - 1, &g) == -1);
    /* the last field is the stream session (wire.md §4 names it so; 0.6.2's header called it reserved) */
    h.session = 0x21222324u;
    vafm_wire_header_encode(&h, b);
    ENSURE(b[68] == 0x24 && b[71] == 0x21);
    ENSURE(vafm_wire_header_decode(b, sizeof b, &g) == 0 && g.session == 0x21222324u && g.reserved == g.session);
    b[0] = 'X';
    ENSURE(vafm_wire_header_decode(b, sizeof b, &g) == -1);
}

int main(void)
{
    enum { CAP = 4096 };
    s_wire_header();
    static uint8_t buf[CAP];
    int decoded = 0, rejected = 0;
    for (size_t i = 0; i < S_N_CORPUS; i++) {
        int r = s_one((const uint8_t *)s_corpus[i], strlen(s_corpus[i]));
        ENSURE_MSG(r >= 0, "corpus %zu: %s", i, s_corpus[i]);
        r > 0 ? decoded++ : rejected++;
    }
    /* the first corpus entries are valid; an oversized request is rejected by size before parsing */
    ENSURE(s_one((const uint8_t *)s_corpus[0], strlen(s_corpus[0])) == 1);
    {
        size_t big = VAFMD_MAX_CMD_BYTES + 1;
        char *b = malloc(big);
        ENSURE(b != NULL);
        if (b) {
            memset(b, ' ', big);
            memcpy(b, s_corpus[0], strlen(s_corpus[0]));
            vafmd_cmd c;
            vafmd_err e = { 0 };
            ENSURE(vafmd_cmd_decode(b, big, &c, &e) == -1 && !strcmp(e.code, VAFMD_E_TOO_LARGE));
            free(b);
        }
    }
    const long iters = LONG_OR(200000, 30000);
    for (long it = 0; it < iters; it++) {
        const char *seed = s_corpus[s_next() % S_N_CORPUS];
        size_t n = strlen(seed);
        memcpy(buf, seed, n);
        int muts = 1 + (int)(s_next() % 4);
        for (int m = 0; m < muts; m++) {
            uint64_t op = s_next() % 5, pos = n ? s_next() % (n + 1) : 0;
            if (op == 0 && n) { /* flip a byte */
                buf[pos % n] ^= (uint8_t)(1u << (s_next() % 8));
            } else if (op == 1 && n) { /* delete a run */
                size_t k = 1 + s_next() % 8;
                if (pos + k > n)
                    k = n - pos;
                memmove(buf + pos, buf + pos + k, n - pos - k);
                n -= k;
            } else if (op == 2) { /* insert a token */
                const char *t = s_tokens[s_next() % (sizeof s_tokens / sizeof *s_tokens)];
                size_t k = strlen(t);
                if (n + k < CAP) {
                    memmove(buf + pos + k, buf + pos, n - pos);
                    memcpy(buf + pos, t, k);
                    n += k;
                }
            } else if (op == 3) { /* truncate */
                n = pos;
            } else { /* splice in the tail of another corpus entry */
                const char *o = s_corpus[s_next() % S_N_CORPUS];
                size_t on = strlen(o), from = on ? s_next() % on : 0;
                if (pos + (on - from) < CAP) {
                    memcpy(buf + pos, o + from, on - from);
                    n = pos + (on - from);
                }
            }
        }
        int r = s_one(buf, n);
        if (r < 0) {
            ENSURE_MSG(0, "iteration %ld: input of %zu bytes broke an invariant: %.*s", it, n, (int)n, (char *)buf);
            break;
        }
        r > 0 ? decoded++ : rejected++;
    }
    printf("fuzz_cmd: %ld mutations + %zu corpus entries: %d decoded, %d rejected\n", iters, S_N_CORPUS, decoded,
           rejected);
    ENSURE(decoded > 0 && rejected > 0);
    return harness_done();
}
#endif
