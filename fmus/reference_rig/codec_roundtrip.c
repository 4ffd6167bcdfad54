/* A check of the codec (and of a port of it): each line of stdin is "KEY DATAGRAM" in hex (KEY "-" for
 * none); each line of stdout is the decode result (0: decoded, enum rig_decode_result), then, if it
 * decoded, the fields and the datagram encoded again, in hex. Used by tests/integration/test_reference_rig.py
 * against fmus/udp_protocol.py.
 *
 *   cc -std=c99 -O2 -Wall -Wextra -o codec_roundtrip codec_roundtrip.c rig_link.c -lm
 */
#include "rig_link.h"

#include <stdio.h>
#include <string.h>

static size_t from_hex(const char *hex, uint8_t *out, size_t cap)
{
    size_t n = 0;
    unsigned byte;
    while (n < cap && sscanf(hex + 2 * n, "%2x", &byte) == 1)
        out[n++] = (uint8_t)byte;
    return n;
}

static void print_hex(const uint8_t *data, size_t len)
{
    size_t i;
    for (i = 0; i < len; i++)
        printf("%02x", data[i]);
}

int main(void)
{
    static char line[2 * 8192 + 16], key_hex[2 * 4096 + 2], data_hex[2 * 2048 + 2];
    static uint8_t secret[4096], data[2048], again[RIG_MAX_DATAGRAM];
    while (fgets(line, sizeof line, stdin)) {
        rig_key key;
        rig_msg m;
        const rig_key *k = NULL;
        size_t len, n;
        uint32_t i;
        enum rig_decode_result res;
        if (sscanf(line, "%8193s %4097s", key_hex, data_hex) != 2)
            continue;
        if (strcmp(key_hex, "-") != 0) {
            rig_key_init(&key, secret, from_hex(key_hex, secret, sizeof secret));
            k = &key;
        }
        len = from_hex(data_hex, data, sizeof data);
        res = rig_decode(data, len, k, &m);
        printf("%d", (int)res);
        if (res == RIG_DECODED) {
            printf(" %u %u %llu %u %llu %.17g %.17g %.17g %u %u %u %u %u %u", m.type, m.flags,
                   (unsigned long long)m.session, m.seq, (unsigned long long)m.t_ns, m.a, m.b, m.c, m.u, m.w,
                   m.horizon, m.fresh, m.predicted, m.uncovered);
            if (m.type == RIG_COMMAND || m.type == RIG_ANSWER)
                for (i = 0; i + 1 < m.u; i++)
                    printf(" %.17g %.17g", m.ahead[i].height_m, m.ahead[i].velocity_m_s);
            n = rig_encode(&m, k, again, sizeof again);
            printf(" ");
            print_hex(again, n);
        }
        printf("\n");
    }
    return 0;
}
