/* pantohil reference rig: the portable rig side of the pantohil rig link, protocol version 3
 * (docs/udp-protocol.md). C99, libc and libm only; no sockets and no clock in here: the caller
 * passes each received datagram with its sender and the time, and sends what comes back.
 *
 *   rig_init(&rig, &config);
 *   on a datagram:  n = rig_handle_datagram(&rig, data, len, &peer, now_ns, reply, sizeof reply);
 *                   if (n) send reply[0..n) to peer
 *   rig-paced:      if (rig_next_tick_ns(&rig) >= 0 && now_ns >= it) {
 *                       n = rig_tick(&rig, now_ns, out, sizeof out); send out to rig_owner(&rig) }
 *   now and then:   rig_expire(&rig, now_ns);
 */
#ifndef PANTOHIL_RIG_LINK_H
#define PANTOHIL_RIG_LINK_H

#include <stddef.h>
#include <stdint.h>

/* ---- the datagrams (docs/udp-protocol.md, "Datagrams") ---- */

#define RIG_MAGIC 0x31484850u /* the bytes "PHH1" little-endian, the same in every version */
#define RIG_VERSION 3
#define RIG_BODY_BYTES 60
#define RIG_CRC_BYTES 4
#define RIG_TAG_BYTES 32
#define RIG_MAX_HORIZON 64 /* heights a COMMAND or ANSWER may carry; the largest horizon granted */
#define RIG_MAX_DATAGRAM (RIG_BODY_BYTES + 16 * (RIG_MAX_HORIZON - 1) + RIG_TAG_BYTES) /* 1100 */
#define RIG_FLAG_AUTHENTICATED 1u

enum rig_type {
    RIG_HELLO = 1, RIG_COMMAND = 2, RIG_FORCE = 3, RIG_STATUS = 4, RIG_BYE = 5, RIG_SAMPLE = 6, RIG_ANSWER = 7
};
enum rig_state { RIG_READY = 0, RIG_RUNNING = 1, RIG_FAULT = 2, RIG_BUSY = 3 };
enum rig_fault_bits {
    RIG_FAULT_VERSION = 1, RIG_FAULT_BAD_HELLO = 2, RIG_FAULT_BUSY = 4, RIG_FAULT_PACING = 8,
    RIG_FAULT_HORIZON = 16
};
enum rig_pacing { RIG_PACED_BY_MODEL = 0, RIG_PACED_BY_RIG = 1 };

/* Why a datagram did not decode. */
enum rig_decode_result {
    RIG_DECODED = 0,
    RIG_E_SIZE,          /* too short, or not the size its type and u give */
    RIG_E_TRAILER,       /* CRC or HMAC wrong */
    RIG_E_MAGIC,
    RIG_E_FLAG,          /* the authenticated flag does not match this side's key */
    RIG_E_TYPE,
    RIG_E_HEIGHTS,       /* a COMMAND or ANSWER whose u is outside 1..64 */
    RIG_E_OTHER_VERSION  /* the magic is ours, the version byte is not 3 */
};

typedef struct rig_height {
    double height_m;
    double velocity_m_s;
} rig_height;

/* One message, every field of every type (meaning by type: docs/udp-protocol.md, "Messages"). */
typedef struct rig_msg {
    uint8_t type;
    uint16_t flags;
    uint64_t session;
    uint32_t seq;
    uint64_t t_ns;
    double a, b, c;
    uint32_t u, w;
    uint32_t horizon;                         /* HELLO: asked for; STATUS: granted */
    uint32_t fresh, predicted, uncovered;     /* FORCE, SAMPLE */
    rig_height ahead[RIG_MAX_HORIZON - 1];    /* COMMAND, ANSWER: heights 2..u (u - 1 of them) */
} rig_msg;

/* ---- CRC-32, SHA-256, HMAC-SHA256 ---- */

uint32_t rig_crc32(const uint8_t *data, size_t len); /* zlib's CRC-32 */

typedef struct rig_sha256 {
    uint32_t h[8];
    uint64_t bytes;
    uint8_t block[64];
    size_t used;
} rig_sha256;

void rig_sha256_init(rig_sha256 *s);
void rig_sha256_update(rig_sha256 *s, const uint8_t *data, size_t len);
void rig_sha256_final(rig_sha256 *s, uint8_t digest[32]);

/* A pre-shared key, kept as the hash states after the padded inner and outer key blocks. */
typedef struct rig_key {
    rig_sha256 inner, outer;
} rig_key;

void rig_key_init(rig_key *key, const uint8_t *secret, size_t len);
void rig_hmac_sha256(const rig_key *key, const uint8_t *data, size_t len, uint8_t tag[32]);

/* ---- codec ---- */

/* The size of a datagram of this type (COMMAND, ANSWER: of u heights); 0 if u is outside 1..64. */
size_t rig_datagram_size(int type, uint32_t u, int authenticated);
/* Encode m (COMMAND and ANSWER carry m->u heights) into out; its size, or 0 if it does not fit or
 * is not a valid message. With a key the trailer is the HMAC and the flags' bit 0 is set. */
size_t rig_encode(const rig_msg *m, const rig_key *key, uint8_t *out, size_t cap);
/* Decode a datagram (with a key: only one carrying that key's valid HMAC). */
enum rig_decode_result rig_decode(const uint8_t *data, size_t len, const rig_key *key, rig_msg *m);
/* A valid HELLO of protocol version 1 or 2 (48 or 64 bytes, CRC trailer): its version, else 0. */
int rig_old_hello_version(const uint8_t *data, size_t len);
/* A STATUS in fault (fault bit 1, a = 3) in version 1's or 2's own layout; its size. out: >= 64 bytes. */
size_t rig_old_refusal(int version, uint64_t session, uint8_t *out);

/* ---- the physics hook: the actuator and what it carries ---- */

/* settle: at a session's start, the actuator at rest at height_m.
 * step: one tick (or step): move the actuator to the reference; returns the measured force [N]
 * (pushing the wire up > 0) and the actuator's height in *actuator_height_m. */
typedef struct rig_physics {
    void *state;
    void (*settle)(void *state, double height_m);
    double (*step)(void *state, double reference_m, double reference_velocity_m_s, double *actuator_height_m);
} rig_physics;

/* An ideal actuator (height = reference, no latency) carrying a rigid mass: the load cell reads
 * f = -m (g + z''), z'' from the Newmark relations with HHT's beta and gamma, exactly as
 * models/pantograph/lumped.py RigidMass. */
typedef struct rig_rigid_mass {
    double mass_kg, gravity_m_s2, dt_s;
    double z_m, v_m_s, acc_m_s2, force_n;
} rig_rigid_mass;

void rig_rigid_mass_init(rig_rigid_mass *r, double mass_kg, double gravity_m_s2, double dt_s);
void rig_rigid_mass_settle(void *state, double height_m);
double rig_rigid_mass_step(void *state, double reference_m, double reference_velocity_m_s,
                           double *actuator_height_m);
rig_physics rig_rigid_mass_physics(rig_rigid_mass *r);

/* ---- the rig: sessions, the horizon, ticks, counters ---- */

#define RIG_ENDED_SESSIONS 4096 /* ids of ended sessions remembered: a replayed HELLO cannot reopen one */
#define RIG_ANSWER_WINDOW 4096  /* rig-paced: samples whose answer is remembered (a power of 2) */
#define RIG_MIN_DT_S 1e-5
#define RIG_MAX_DT_S 1.0

/* The sender of a datagram, as opaque bytes compared whole (main.c puts a zeroed sockaddr_in in). */
typedef struct rig_peer {
    uint8_t bytes[32];
    uint32_t len;
} rig_peer;

typedef struct rig_counters {
    uint64_t sessions, commands, answers, samples, answered;
    uint64_t malformed, old_version, unexpected, foreign, nonfinite, bad_hello, replayed, doubled;
    uint64_t fresh, predicted, uncovered;
    double max_abs_height_m;
} rig_counters;

/* The newest COMMAND executed or ANSWER taken: its seq and its heights (docs/udp-protocol.md,
 * "Which height a tick takes"). */
typedef struct rig_horizon {
    int valid;
    uint32_t seq;
    uint32_t count;
    rig_height heights[RIG_MAX_HORIZON];
} rig_horizon;

typedef struct rig_session {
    int active;
    uint64_t number, id;
    rig_peer owner;
    int pacing;
    double dt_s;
    uint32_t horizon;
    int64_t last_heard_ns;
    int started;           /* rig-paced: ANSWER 0 has come, the loop runs */
    int64_t start_ns;      /* rig-paced: when ANSWER 0 came; tick k is due at start + k dt */
    uint32_t step;         /* the last step executed (model-paced) or tick sent (rig-paced) */
    rig_horizon newest;
    double reference_m, reference_velocity_m_s; /* the actuator's last reference, held when uncovered */
    double force_n, actuator_m;
    rig_counters counts;   /* this session's share */
    uint8_t answered[RIG_ANSWER_WINDOW / 8];
} rig_session;

enum rig_event { RIG_SESSION_OPENED, RIG_SESSION_CLOSED };

struct rig;
typedef void (*rig_event_fn)(void *ctx, const struct rig *rig, enum rig_event event, const char *why);

typedef struct rig_config {
    int pacing;                 /* the one pacing this rig runs */
    double dt_s;                /* its step or tick; a HELLO must ask for it (within 1e-6 relative) */
    uint32_t latency_steps;     /* reported by STATUS */
    uint32_t max_horizon;       /* the largest horizon granted, 1..64 */
    int64_t session_timeout_ns; /* a session whose owner is silent this long ends */
    const rig_key *key;         /* NULL: CRC trailers, no HMAC */
    rig_physics physics;
    rig_event_fn on_event;      /* may be NULL */
    void *event_ctx;
} rig_config;

typedef struct rig {
    rig_config config;
    rig_counters counts;
    rig_session session;        /* the running one, or the last one ended (active = 0) */
    uint64_t ended[RIG_ENDED_SESSIONS];
    uint32_t ended_count, ended_next;
} rig;

void rig_init(rig *r, const rig_config *config);
/* Handle one datagram from peer at now_ns; returns the size of the reply to send back to peer
 * (STATUS, FORCE, or an old version's refusal), 0 for none. reply: RIG_MAX_DATAGRAM bytes. */
size_t rig_handle_datagram(rig *r, const uint8_t *data, size_t len, const rig_peer *peer, int64_t now_ns,
                           uint8_t *reply, size_t reply_cap);
/* Rig-paced: when the next tick is due (monotonic ns), or -1 if no loop runs. */
int64_t rig_next_tick_ns(const rig *r);
/* Rig-paced: run the due tick; returns the size of its SAMPLE, to be sent to rig_owner(). */
size_t rig_tick(rig *r, int64_t now_ns, uint8_t *out, size_t cap);
const rig_peer *rig_owner(const rig *r);
/* End a session whose owner has been silent for the session timeout; 1 if one ended. */
int rig_expire(rig *r, int64_t now_ns);
/* End the running session (the program stops); why goes to the event. */
void rig_close(rig *r, const char *why);

#endif
