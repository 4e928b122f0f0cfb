/* SPDX-License-Identifier: MIT */
/* Example of the C client (include/vafm/client.h): subscribe, start one force curve, print its blocks.
 *
 *   example_subscribe [REP_ENDPOINT [PUB_ENDPOINT [INDEX]]]
 *
 * Defaults: tcp://127.0.0.1:5555, tcp://127.0.0.1:5556, index 0. Exit status 0 when the run ended "ok"
 * without a sequence gap, 1 otherwise. */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "vafm/client.h"

int main(int argc, char **argv)
{
    const char *rep = argc > 1 ? argv[1] : NULL, *pub = argc > 2 ? argv[2] : NULL;
    long index = argc > 3 ? strtol(argv[3], NULL, 10) : 0;
    vafm_error e = {0};
    vafm_client *c = NULL;
    int rc = vafm_client_new(&c, rep, pub, &e);
    /* Subscribe first: the daemon confirms the subscription, so the run is seen from its first block. */
    if (!rc)
        rc = vafm_client_subscribe(c, 5000, &e);
    char req[96], *reply = NULL;
    snprintf(req, sizeof req, "{\"cmd\": \"curve\", \"index\": %ld}", index);
    if (!rc)
        rc = vafm_client_request(c, req, 5000, &reply, &e);
    if (rc) {
        fprintf(stderr, "example_subscribe: %s\n", e.message);
        free(reply);
        vafm_client_destroy(&c);
        return 1;
    }
    printf("reply %s\n", reply);
    free(reply);

    vafm_client_msg m = {0};
    int64_t run = -1;
    int ok = 0;
    for (;;) {
        rc = vafm_client_receive(c, &m, 20000, &e);
        if (rc) {
            fprintf(stderr, "example_subscribe: %s\n", e.message);
            break;
        }
        if (m.kind == VAFM_MSG_RUN_START && run < 0) {
            run = m.run_id;
            printf("run.start run %" PRId64 " kind %s index %" PRId64 " fs %.6g Hz channels", run, m.run_kind,
                   m.index, m.sample_rate_Hz);
            for (size_t k = 0; k < m.n_channel_names; k++)
                printf(" %s", m.channel_names[k]);
            printf("\n");
        } else if (m.kind == VAFM_MSG_DATA && m.run_id == run) {
            const vafm_wire_header *h = &m.header;
            printf("block %" PRIu64 " seq %" PRIu64 " first %" PRIu64 " n %" PRIu32 " seg %u flags %#x"
                   " height[0] %.6g m force[0] %.6g N%s\n",
                   h->block_index, h->seq, h->first_sample, h->n_samples, h->segment, h->flags, m.channels[0][0],
                   m.channels[2][0], m.gap ? " GAP" : "");
        } else if (m.kind == VAFM_MSG_EVENT && m.run_id == run) {
            printf("event %s %s\n", m.event_kind, m.json);
        } else if (m.kind == VAFM_MSG_RUN_END && m.run_id == run) {
            printf("run.end status %s samples %" PRId64 " gaps %" PRIu64 "\n", m.status, m.samples,
                   vafm_client_gaps(c));
            ok = !strcmp(m.status, "ok") && vafm_client_gaps(c) == 0;
            break;
        }
    }
    vafm_client_msg_clear(&m);
    vafm_client_destroy(&c);
    return ok ? 0 : 1;
}
