/* pantohil reference rig: codec, session, horizon and tick logic of the rig link, protocol version 3
 * (docs/udp-protocol.md). Portable C99: no sockets, no clock, no allocation. Assumes IEEE-754 doubles. */
#include "rig_link.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

/* ---- little-endian fields ---- */

static void put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}

static void put_u32(uint8_t *p, uint32_t v)
{
    int i;
    for (i = 0; i < 4; i++)
        p[i] = (uint8_t)(v >> (8 * i));
}

static void put_u64(uint8_t *p, uint64_t v)
{
    int i;
    for (i = 0; i < 8; i++)
        p[i] = (uint8_t)(v >> (8 * i));
}

static void put_f64(uint8_t *p, double v)
{
    uint64_t bits;
    memcpy(&bits, &v, sizeof bits);
    put_u64(p, bits);
}

static uint16_t get_u16(const uint8_t *p)
{
    return (uint16_t)(p[0] | (p[1] << 8));
}

static uint32_t get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static uint64_t get_u64(const uint8_t *p)
{
    return (uint64_t)get_u32(p) | ((uint64_t)get_u32(p + 4) << 32);
}

static double get_f64(const uint8_t *p)
{
    uint64_t bits = get_u64(p);
    double v;
    memcpy(&v, &bits, sizeof v);
    return v;
}

/* ---- CRC-32 (zlib: reflected polynomial 0xEDB88320, initial and final value all ones) ---- */

static uint32_t crc_table[256];
static int crc_table_ready;

static void crc_table_build(void)
{
    uint32_t n, c;
    int k;
    for (n = 0; n < 256; n++) {
        c = n;
        for (k = 0; k < 8; k++)
            c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
        crc_table[n] = c;
    }
    crc_table_ready = 1;
}

uint32_t rig_crc32(const uint8_t *data, size_t len)
{
    uint32_t c = 0xFFFFFFFFu;
    size_t i;
    if (!crc_table_ready)
        crc_table_build();
    for (i = 0; i < len; i++)
        c = crc_table[(c ^ data[i]) & 0xFFu] ^ (c >> 8);
    return c ^ 0xFFFFFFFFu;
}

/* ---- SHA-256 (FIPS 180-4 sec. 6.2) ---- */

static const uint32_t sha256_k[64] = {
    0x428a2f98u, 0x71374491u, 0xb5c0fbcfu, 0xe9b5dba5u, 0x3956c25bu, 0x59f111f1u, 0x923f82a4u, 0xab1c5ed5u,
    0xd807aa98u, 0x12835b01u, 0x243185beu, 0x550c7dc3u, 0x72be5d74u, 0x80deb1feu, 0x9bdc06a7u, 0xc19bf174u,
    0xe49b69c1u, 0xefbe4786u, 0x0fc19dc6u, 0x240ca1ccu, 0x2de92c6fu, 0x4a7484aau, 0x5cb0a9dcu, 0x76f988dau,
    0x983e5152u, 0xa831c66du, 0xb00327c8u, 0xbf597fc7u, 0xc6e00bf3u, 0xd5a79147u, 0x06ca6351u, 0x14292967u,
    0x27b70a85u, 0x2e1b2138u, 0x4d2c6dfcu, 0x53380d13u, 0x650a7354u, 0x766a0abbu, 0x81c2c92eu, 0x92722c85u,
    0xa2bfe8a1u, 0xa81a664bu, 0xc24b8b70u, 0xc76c51a3u, 0xd192e819u, 0xd6990624u, 0xf40e3585u, 0x106aa070u,
    0x19a4c116u, 0x1e376c08u, 0x2748774cu, 0x34b0bcb5u, 0x391c0cb3u, 0x4ed8aa4au, 0x5b9cca4fu, 0x682e6ff3u,
    0x748f82eeu, 0x78a5636fu, 0x84c87814u, 0x8cc70208u, 0x90befffau, 0xa4506cebu, 0xbef9a3f7u, 0xc67178f2u,
};

static uint32_t rotr(uint32_t x, int n)
{
    return (x >> n) | (x << (32 - n));
}

static void sha256_block(uint32_t h[8], const uint8_t block[64])
{
    uint32_t w[64], v[8], t1, t2;
    int t;
    for (t = 0; t < 16; t++)
        w[t] = ((uint32_t)block[4 * t] << 24) | ((uint32_t)block[4 * t + 1] << 16)
             | ((uint32_t)block[4 * t + 2] << 8) | (uint32_t)block[4 * t + 3];
    for (t = 16; t < 64; t++) {
        uint32_t s0 = rotr(w[t - 15], 7) ^ rotr(w[t - 15], 18) ^ (w[t - 15] >> 3);
        uint32_t s1 = rotr(w[t - 2], 17) ^ rotr(w[t - 2], 19) ^ (w[t - 2] >> 10);
        w[t] = w[t - 16] + s0 + w[t - 7] + s1;
    }
    memcpy(v, h, sizeof v);
    for (t = 0; t < 64; t++) {
        /* v[0..7] = a, b, c, d, e, f, g, h of the standard */
        t1 = v[7] + (rotr(v[4], 6) ^ rotr(v[4], 11) ^ rotr(v[4], 25)) + ((v[4] & v[5]) ^ (~v[4] & v[6]))
           + sha256_k[t] + w[t];
        t2 = (rotr(v[0], 2) ^ rotr(v[0], 13) ^ rotr(v[0], 22)) + ((v[0] & v[1]) ^ (v[0] & v[2]) ^ (v[1] & v[2]));
        v[7] = v[6];
        v[6] = v[5];
        v[5] = v[4];
        v[4] = v[3] + t1;
        v[3] = v[2];
        v[2] = v[1];
        v[1] = v[0];
        v[0] = t1 + t2;
    }
    for (t = 0; t < 8; t++)
        h[t] += v[t];
}

void rig_sha256_init(rig_sha256 *s)
{
    static const uint32_t h0[8] = {0x6a09e667u, 0xbb67ae85u, 0x3c6ef372u, 0xa54ff53au,
                                   0x510e527fu, 0x9b05688cu, 0x1f83d9abu, 0x5be0cd19u};
    memcpy(s->h, h0, sizeof h0);
    s->bytes = 0;
    s->used = 0;
}

void rig_sha256_update(rig_sha256 *s, const uint8_t *data, size_t len)
{
    s->bytes += len;
    while (len > 0) {
        size_t take = 64 - s->used < len ? 64 - s->used : len;
        memcpy(s->block + s->used, data, take);
        s->used += take;
        data += take;
        len -= take;
        if (s->used == 64) {
            sha256_block(s->h, s->block);
            s->used = 0;
        }
    }
}

void rig_sha256_final(rig_sha256 *s, uint8_t digest[32])
{
    uint64_t bits = s->bytes * 8;
    int i;
    s->block[s->used++] = 0x80;
    if (s->used > 56) {
        memset(s->block + s->used, 0, 64 - s->used);
        sha256_block(s->h, s->block);
        s->used = 0;
    }
    memset(s->block + s->used, 0, 56 - s->used);
    for (i = 0; i < 8; i++)
        s->block[56 + i] = (uint8_t)(bits >> (56 - 8 * i));
    sha256_block(s->h, s->block);
    for (i = 0; i < 8; i++) {
        digest[4 * i] = (uint8_t)(s->h[i] >> 24);
        digest[4 * i + 1] = (uint8_t)(s->h[i] >> 16);
        digest[4 * i + 2] = (uint8_t)(s->h[i] >> 8);
        digest[4 * i + 3] = (uint8_t)s->h[i];
    }
}

/* ---- HMAC-SHA256 (RFC 2104, FIPS 198-1) ---- */

void rig_key_init(rig_key *key, const uint8_t *secret, size_t len)
{
    uint8_t k0[64], pad[64];
    int i;
    memset(k0, 0, sizeof k0);
    if (len > 64) { /* a key longer than the block is hashed first */
        rig_sha256 s;
        rig_sha256_init(&s);
        rig_sha256_update(&s, secret, len);
        rig_sha256_final(&s, k0);
    } else {
        memcpy(k0, secret, len);
    }
    for (i = 0; i < 64; i++)
        pad[i] = k0[i] ^ 0x36;
    rig_sha256_init(&key->inner);
    rig_sha256_update(&key->inner, pad, 64);
    for (i = 0; i < 64; i++)
        pad[i] = k0[i] ^ 0x5c;
    rig_sha256_init(&key->outer);
    rig_sha256_update(&key->outer, pad, 64);
}

void rig_hmac_sha256(const rig_key *key, const uint8_t *data, size_t len, uint8_t tag[32])
{
    rig_sha256 s = key->inner;
    uint8_t inner[32];
    rig_sha256_update(&s, data, len);
    rig_sha256_final(&s, inner);
    s = key->outer;
    rig_sha256_update(&s, inner, sizeof inner);
    rig_sha256_final(&s, tag);
}

static int same_tag(const uint8_t *x, const uint8_t *y)
{
    uint8_t diff = 0;
    int i;
    for (i = 0; i < RIG_TAG_BYTES; i++) /* the time taken does not tell how many bytes matched */
        diff |= (uint8_t)(x[i] ^ y[i]);
    return diff == 0;
}

/* ---- codec (docs/udp-protocol.md, "Datagrams") ---- */

static int valid_type(int type)
{
    return type >= RIG_HELLO && type <= RIG_ANSWER;
}

/* Bytes of a type's extension; -1 for a COMMAND or ANSWER whose height count u is outside 1..64. */
static long extension_bytes(int type, uint32_t u)
{
    switch (type) {
    case RIG_HELLO:
    case RIG_STATUS:
        return 4;
    case RIG_COMMAND:
    case RIG_ANSWER:
        return u >= 1 && u <= RIG_MAX_HORIZON ? 16L * (long)(u - 1) : -1;
    case RIG_FORCE:
    case RIG_SAMPLE:
        return 12;
    default:
        return 0;
    }
}

size_t rig_datagram_size(int type, uint32_t u, int authenticated)
{
    long ext = extension_bytes(type, u);
    if (!valid_type(type) || ext < 0)
        return 0;
    return RIG_BODY_BYTES + (size_t)ext + (authenticated ? RIG_TAG_BYTES : RIG_CRC_BYTES);
}

static void encode_extension(const rig_msg *m, uint8_t *p)
{
    uint32_t i;
    switch (m->type) {
    case RIG_HELLO:
    case RIG_STATUS:
        put_u32(p, m->horizon);
        break;
    case RIG_COMMAND:
    case RIG_ANSWER:
        for (i = 0; i + 1 < m->u; i++) {
            put_f64(p + 16 * i, m->ahead[i].height_m);
            put_f64(p + 16 * i + 8, m->ahead[i].velocity_m_s);
        }
        break;
    case RIG_FORCE:
    case RIG_SAMPLE:
        put_u32(p, m->fresh);
        put_u32(p + 4, m->predicted);
        put_u32(p + 8, m->uncovered);
        break;
    default:
        break;
    }
}

size_t rig_encode(const rig_msg *m, const rig_key *key, uint8_t *out, size_t cap)
{
    size_t size = rig_datagram_size(m->type, m->u, key != NULL);
    size_t body;
    if (size == 0 || size > cap)
        return 0;
    body = size - (key ? RIG_TAG_BYTES : RIG_CRC_BYTES);
    put_u32(out, RIG_MAGIC);
    out[4] = RIG_VERSION;
    out[5] = m->type;
    put_u16(out + 6, key ? RIG_FLAG_AUTHENTICATED : 0);
    put_u64(out + 8, m->session);
    put_u32(out + 16, m->seq);
    put_u64(out + 20, m->t_ns);
    put_f64(out + 28, m->a);
    put_f64(out + 36, m->b);
    put_f64(out + 44, m->c);
    put_u32(out + 52, m->u);
    put_u32(out + 56, m->w);
    encode_extension(m, out + RIG_BODY_BYTES);
    if (key)
        rig_hmac_sha256(key, out, body, out + body);
    else
        put_u32(out + body, rig_crc32(out, body));
    return size;
}

static void decode_extension(const uint8_t *p, rig_msg *m)
{
    uint32_t i;
    switch (m->type) {
    case RIG_HELLO:
    case RIG_STATUS:
        m->horizon = get_u32(p);
        break;
    case RIG_COMMAND:
    case RIG_ANSWER:
        for (i = 0; i + 1 < m->u; i++) {
            m->ahead[i].height_m = get_f64(p + 16 * i);
            m->ahead[i].velocity_m_s = get_f64(p + 16 * i + 8);
        }
        break;
    case RIG_FORCE:
    case RIG_SAMPLE:
        m->fresh = get_u32(p);
        m->predicted = get_u32(p + 4);
        m->uncovered = get_u32(p + 8);
        break;
    default:
        break;
    }
}

/* The checks in the order of fmus/udp_protocol.py decode(), so both sides name the same reason. */
enum rig_decode_result rig_decode(const uint8_t *data, size_t len, const rig_key *key, rig_msg *m)
{
    size_t trailer = key ? RIG_TAG_BYTES : RIG_CRC_BYTES, body;
    long ext;
    memset(m, 0, sizeof *m);
    if (len >= 6 && get_u32(data) == RIG_MAGIC && data[4] != RIG_VERSION)
        return RIG_E_OTHER_VERSION;
    if (len < RIG_BODY_BYTES + trailer)
        return RIG_E_SIZE;
    body = len - trailer;
    if (key) {
        uint8_t tag[RIG_TAG_BYTES];
        rig_hmac_sha256(key, data, body, tag);
        if (!same_tag(tag, data + body))
            return RIG_E_TRAILER;
    } else if (rig_crc32(data, body) != get_u32(data + body)) {
        return RIG_E_TRAILER;
    }
    if (get_u32(data) != RIG_MAGIC)
        return RIG_E_MAGIC;
    m->type = data[5];
    m->flags = get_u16(data + 6);
    if (((m->flags & RIG_FLAG_AUTHENTICATED) != 0) != (key != NULL))
        return RIG_E_FLAG;
    if (!valid_type(m->type))
        return RIG_E_TYPE;
    m->u = get_u32(data + 52);
    ext = extension_bytes(m->type, m->u);
    if (ext < 0)
        return RIG_E_HEIGHTS;
    if (body != RIG_BODY_BYTES + (size_t)ext)
        return RIG_E_SIZE;
    m->session = get_u64(data + 8);
    m->seq = get_u32(data + 16);
    m->t_ns = get_u64(data + 20);
    m->a = get_f64(data + 28);
    m->b = get_f64(data + 36);
    m->c = get_f64(data + 44);
    m->w = get_u32(data + 56);
    decode_extension(data + RIG_BODY_BYTES, m);
    return RIG_DECODED;
}

/* ---- older versions (docs/udp-protocol.md, "Other protocol versions") ---- */

#define RIG_V1_BYTES 48 /* version 1: magic, version, type, flags, seq u32, t_ns, a, b, u, w, CRC */
#define RIG_V2_BYTES 64 /* version 2: version 3's body without extension, CRC */

int rig_old_hello_version(const uint8_t *data, size_t len)
{
    int version;
    if (len == RIG_V1_BYTES)
        version = 1;
    else if (len == RIG_V2_BYTES)
        version = 2;
    else
        return 0;
    if (rig_crc32(data, len - 4) != get_u32(data + len - 4))
        return 0;
    if (get_u32(data) != RIG_MAGIC || data[4] != version || data[5] != RIG_HELLO)
        return 0;
    return version;
}

size_t rig_old_refusal(int version, uint64_t session, uint8_t *out)
{
    size_t body;
    memset(out, 0, RIG_V2_BYTES);
    put_u32(out, RIG_MAGIC);
    out[4] = (uint8_t)version;
    out[5] = RIG_STATUS;
    if (version == 1) { /* <IBBHIQddII: no session id in version 1 */
        put_f64(out + 20, (double)RIG_VERSION);
        put_u32(out + 36, RIG_FAULT);
        put_u32(out + 40, RIG_FAULT_VERSION);
        body = RIG_V1_BYTES - 4;
    } else {
        put_u64(out + 8, session);
        put_f64(out + 28, (double)RIG_VERSION);
        put_u32(out + 52, RIG_FAULT);
        put_u32(out + 56, RIG_FAULT_VERSION);
        body = RIG_V2_BYTES - 4;
    }
    put_u32(out + body, rig_crc32(out, body));
    return body + 4;
}

/* ---- the rigid mass on an ideal actuator (models/pantograph/lumped.py RigidMass) ---- */

#define HHT_BETA 0.2756
#define HHT_GAMMA 0.55

void rig_rigid_mass_init(rig_rigid_mass *r, double mass_kg, double gravity_m_s2, double dt_s)
{
    r->mass_kg = mass_kg;
    r->gravity_m_s2 = gravity_m_s2;
    r->dt_s = dt_s;
    rig_rigid_mass_settle(r, 0.0);
}

void rig_rigid_mass_settle(void *state, double height_m)
{
    rig_rigid_mass *r = state;
    r->z_m = height_m;
    r->v_m_s = 0.0;
    r->acc_m_s2 = 0.0;
    r->force_n = -r->mass_kg * r->gravity_m_s2;
}

/* The operations in RigidMass.step's order, so the force is the same to the bit (with
 * floating-point contraction off: no fused multiply-add). */
double rig_rigid_mass_step(void *state, double reference_m, double reference_velocity_m_s,
                           double *actuator_height_m)
{
    rig_rigid_mass *r = state;
    const double b = HHT_BETA, g = HHT_GAMMA, dt = r->dt_s;
    double acc_new = (reference_m - r->z_m - dt * r->v_m_s - dt * dt * (0.5 - b) * r->acc_m_s2) / (b * dt * dt);
    (void)reference_velocity_m_s; /* the ideal actuator follows the height; the mass differentiates it */
    r->v_m_s += dt * ((1 - g) * r->acc_m_s2 + g * acc_new);
    r->acc_m_s2 = acc_new;
    r->z_m = reference_m;
    r->force_n = -r->mass_kg * (r->gravity_m_s2 + acc_new);
    *actuator_height_m = r->z_m;
    return r->force_n;
}

rig_physics rig_rigid_mass_physics(rig_rigid_mass *r)
{
    rig_physics p;
    p.state = r;
    p.settle = rig_rigid_mass_settle;
    p.step = rig_rigid_mass_step;
    return p;
}

/* ---- the rig ---- */

void rig_init(rig *r, const rig_config *config)
{
    memset(r, 0, sizeof *r);
    r->config = *config;
    if (r->config.max_horizon < 1 || r->config.max_horizon > RIG_MAX_HORIZON)
        r->config.max_horizon = RIG_MAX_HORIZON;
    if (!crc_table_ready)
        crc_table_build();
}

const rig_peer *rig_owner(const rig *r)
{
    return &r->session.owner;
}

static int same_peer(const rig_peer *x, const rig_peer *y)
{
    return x->len == y->len && memcmp(x->bytes, y->bytes, x->len) == 0;
}

static int finite_msg(const rig_msg *m)
{
    uint32_t i;
    if (!isfinite(m->a) || !isfinite(m->b) || !isfinite(m->c))
        return 0;
    if (m->type == RIG_COMMAND || m->type == RIG_ANSWER)
        for (i = 0; i + 1 < m->u; i++)
            if (!isfinite(m->ahead[i].height_m) || !isfinite(m->ahead[i].velocity_m_s))
                return 0;
    return 1;
}

static void event(rig *r, enum rig_event e, const char *why)
{
    if (r->config.on_event)
        r->config.on_event(r->config.event_ctx, r, e, why);
}

static int session_ended(const rig *r, uint64_t id)
{
    uint32_t i;
    for (i = 0; i < r->ended_count; i++)
        if (r->ended[i] == id)
            return 1;
    return 0;
}

static void remember_ended(rig *r, uint64_t id)
{
    r->ended[r->ended_next] = id;
    r->ended_next = (r->ended_next + 1) % RIG_ENDED_SESSIONS;
    if (r->ended_count < RIG_ENDED_SESSIONS)
        r->ended_count++;
}

void rig_close(rig *r, const char *why)
{
    if (!r->session.active)
        return;
    remember_ended(r, r->session.id);
    r->session.active = 0; /* the actuator holds its last position: no more steps are taken */
    event(r, RIG_SESSION_CLOSED, why);
}

int rig_expire(rig *r, int64_t now_ns)
{
    char why[96];
    if (!r->session.active || now_ns - r->session.last_heard_ns <= r->config.session_timeout_ns)
        return 0;
    snprintf(why, sizeof why, "expired: no datagram from its owner for %g s",
             (double)r->config.session_timeout_ns * 1e-9);
    rig_close(r, why);
    return 1;
}

static void open_session(rig *r, const rig_msg *hello, const rig_peer *peer, int64_t now_ns)
{
    rig_session *s = &r->session;
    memset(s, 0, sizeof *s);
    s->active = 1;
    s->number = ++r->counts.sessions;
    s->id = hello->session;
    s->owner = *peer;
    s->pacing = (int)hello->u;
    s->dt_s = hello->a;
    s->horizon = hello->horizon;
    s->last_heard_ns = now_ns;
    r->config.physics.settle(r->config.physics.state, 0.0);
    event(r, RIG_SESSION_OPENED, "");
}

static size_t status(const rig *r, uint64_t session, uint32_t state, uint32_t faults, uint32_t horizon,
                     uint8_t *out, size_t cap)
{
    rig_msg m;
    memset(&m, 0, sizeof m);
    m.type = RIG_STATUS;
    m.session = session;
    m.a = (double)r->config.latency_steps;
    m.b = r->config.dt_s;
    m.c = (double)r->config.pacing;
    m.u = state;
    m.w = faults;
    m.horizon = horizon;
    return rig_encode(&m, r->config.key, out, cap);
}

/* The fault bits a HELLO of no running session earns (docs/udp-protocol.md, "A session" 1.). */
static uint32_t hello_faults(const rig *r, const rig_msg *m)
{
    uint32_t faults = 0;
    double dt = r->config.dt_s;
    if (m->a < RIG_MIN_DT_S || m->a > RIG_MAX_DT_S || m->session == 0 || m->u > RIG_PACED_BY_RIG
        || fabs(m->a - dt) > 1e-6 * dt)
        faults |= RIG_FAULT_BAD_HELLO;
    if (m->u <= RIG_PACED_BY_RIG && (int)m->u != r->config.pacing)
        faults |= RIG_FAULT_BAD_HELLO | RIG_FAULT_PACING;
    if (m->horizon < 1 || m->horizon > r->config.max_horizon)
        faults |= RIG_FAULT_HORIZON;
    return faults;
}

static size_t hello(rig *r, const rig_msg *m, const rig_peer *peer, int64_t now_ns, uint8_t *out, size_t cap)
{
    rig_session *s = &r->session;
    uint32_t faults;
    if (s->active && (!same_peer(peer, &s->owner) || m->session != s->id)) {
        r->counts.foreign++;
        s->counts.foreign++;
        return status(r, m->session, RIG_BUSY, RIG_FAULT_BUSY, 0, out, cap);
    }
    if (!finite_msg(m)) {
        r->counts.nonfinite++;
        return status(r, m->session, RIG_FAULT, RIG_FAULT_BAD_HELLO, 0, out, cap);
    }
    if (!s->active && session_ended(r, m->session)) { /* a recorded HELLO: the ended session stays ended */
        r->counts.replayed++;
        return status(r, m->session, RIG_FAULT, RIG_FAULT_BAD_HELLO, 0, out, cap);
    }
    faults = hello_faults(r, m);
    if (faults) {
        r->counts.bad_hello++;
        return status(r, m->session, RIG_FAULT, faults, 0, out, cap);
    }
    if (!s->active)
        open_session(r, m, peer, now_ns);
    else
        s->last_heard_ns = now_ns; /* the owner's repeated HELLO: answered again, no reset */
    return status(r, m->session, RIG_READY, 0, s->horizon, out, cap);
}

static void take_horizon(rig_horizon *h, const rig_msg *m)
{
    h->valid = 1;
    h->seq = m->seq;
    h->count = m->u;
    h->heights[0].height_m = m->a;
    h->heights[0].velocity_m_s = m->b;
    memcpy(h->heights + 1, m->ahead, sizeof(rig_height) * (m->u - 1));
}

enum tick_source { FRESH, PREDICTED, UNCOVERED };

/* One step of the actuator and what it carries, from the height h (NULL: no height covers the
 * step; the actuator holds its last reference), counted by where the height came from. */
static void execute(rig *r, const rig_height *h, enum tick_source source)
{
    rig_session *s = &r->session;
    if (h) {
        s->reference_m = h->height_m;
        s->reference_velocity_m_s = h->velocity_m_s;
    } else {
        s->reference_velocity_m_s = 0.0;
    }
    s->force_n = r->config.physics.step(r->config.physics.state, s->reference_m, s->reference_velocity_m_s,
                                        &s->actuator_m);
    if (fabs(s->reference_m) > s->counts.max_abs_height_m)
        s->counts.max_abs_height_m = fabs(s->reference_m);
    if (fabs(s->reference_m) > r->counts.max_abs_height_m)
        r->counts.max_abs_height_m = fabs(s->reference_m);
    if (source == FRESH) {
        s->counts.fresh++;
        r->counts.fresh++;
    } else if (source == PREDICTED) {
        s->counts.predicted++;
        r->counts.predicted++;
    } else {
        s->counts.uncovered++;
        r->counts.uncovered++;
    }
}

/* A step skipped (its COMMAND lost), from the newest executed COMMAND's horizon if it covers it:
 * COMMAND a's i-th height is for step a + i - 1. */
static void execute_skipped(rig *r, uint32_t step)
{
    const rig_horizon *h = &r->session.newest;
    if (h->valid && step - h->seq < h->count)
        execute(r, &h->heights[step - h->seq], PREDICTED);
    else
        execute(r, NULL, UNCOVERED);
}

static size_t reply_counts(const rig *r, uint8_t type, uint32_t seq, uint64_t t_ns, uint8_t *out, size_t cap)
{
    const rig_session *s = &r->session;
    rig_msg m;
    memset(&m, 0, sizeof m);
    m.type = type;
    m.session = s->id;
    m.seq = seq;
    m.t_ns = t_ns;
    m.a = s->force_n;
    m.b = s->actuator_m;
    m.u = RIG_RUNNING;
    m.w = type == RIG_SAMPLE ? (uint32_t)s->counts.uncovered : 0;
    m.fresh = (uint32_t)s->counts.fresh;
    m.predicted = (uint32_t)s->counts.predicted;
    m.uncovered = (uint32_t)s->counts.uncovered;
    return rig_encode(&m, r->config.key, out, cap);
}

/* Model-paced (docs/udp-protocol.md, "Which height a tick takes"): COMMAND k is executed only if k is
 * above the newest executed step; skipped steps first; the FORCE answers step k only. */
static size_t command(rig *r, const rig_msg *m, uint8_t *out, size_t cap)
{
    rig_session *s = &r->session;
    size_t n;
    if (m->seq <= s->step) { /* a duplicate, a late one or a replay */
        r->counts.replayed++;
        s->counts.replayed++;
        return 0;
    }
    if (m->seq - s->step > RIG_ANSWER_WINDOW) /* at most a window of skipped steps is executed */
        s->step = m->seq - RIG_ANSWER_WINDOW;
    while (s->step + 1 < m->seq)
        execute_skipped(r, ++s->step);
    take_horizon(&s->newest, m);
    s->step = m->seq;
    execute(r, &s->newest.heights[0], FRESH);
    r->counts.commands++;
    s->counts.commands++;
    n = reply_counts(r, RIG_FORCE, m->seq, m->t_ns, out, cap);
    if (n) {
        r->counts.answers++;
        s->counts.answers++;
    }
    return n;
}

static int answered(const rig_session *s, uint32_t seq)
{
    uint32_t i = seq % RIG_ANSWER_WINDOW;
    return (s->answered[i / 8] >> (i % 8)) & 1;
}

static void mark_answered(rig_session *s, uint32_t seq, int yes)
{
    uint32_t i = seq % RIG_ANSWER_WINDOW;
    if (yes)
        s->answered[i / 8] |= (uint8_t)(1u << (i % 8));
    else
        s->answered[i / 8] &= (uint8_t)~(1u << (i % 8));
}

/* Rig-paced: ANSWER 0 starts the loop; an answer to a sample not yet answered is taken if it is the
 * newest (older ones arriving later are never used). */
static void answer(rig *r, const rig_msg *m, int64_t now_ns)
{
    rig_session *s = &r->session;
    if (!s->started) {
        if (m->seq != 0) {
            r->counts.unexpected++;
            return;
        }
        s->started = 1;
        s->start_ns = now_ns;
        take_horizon(&s->newest, m);
        r->counts.commands++;
        s->counts.commands++;
        return;
    }
    if (m->seq > s->step) { /* an answer to a sample not sent */
        r->counts.unexpected++;
        return;
    }
    if (m->seq == 0 || s->step - m->seq >= RIG_ANSWER_WINDOW || answered(s, m->seq)) {
        r->counts.doubled++;
        s->counts.doubled++;
        return;
    }
    mark_answered(s, m->seq, 1);
    r->counts.answered++;
    s->counts.answered++;
    if (m->seq > s->newest.seq) {
        take_horizon(&s->newest, m);
        r->counts.commands++;
        s->counts.commands++;
    }
}

int64_t rig_next_tick_ns(const rig *r)
{
    const rig_session *s = &r->session;
    if (!s->active || s->pacing != RIG_PACED_BY_RIG || !s->started)
        return -1;
    return s->start_ns + (int64_t)llround((double)(s->step + 1) * s->dt_s * 1e9);
}

size_t rig_tick(rig *r, int64_t now_ns, uint8_t *out, size_t cap)
{
    rig_session *s = &r->session;
    const rig_horizon *h = &s->newest;
    uint32_t k, ahead;
    size_t n;
    (void)now_ns;
    if (rig_next_tick_ns(r) < 0)
        return 0;
    k = ++s->step;
    mark_answered(s, k, 0);
    ahead = k - h->seq; /* >= 1: no answer to a sample not yet sent is taken */
    if (ahead >= 1 && ahead <= h->count)
        execute(r, &h->heights[ahead - 1], ahead == 1 ? FRESH : PREDICTED);
    else
        execute(r, NULL, UNCOVERED);
    n = reply_counts(r, RIG_SAMPLE, k, (uint64_t)llround((double)k * s->dt_s * 1e9), out, cap);
    r->counts.samples++;
    s->counts.samples++;
    if (n) {
        r->counts.answers++;
        s->counts.answers++;
    }
    return n;
}

size_t rig_handle_datagram(rig *r, const uint8_t *data, size_t len, const rig_peer *peer, int64_t now_ns,
                           uint8_t *reply, size_t reply_cap)
{
    rig_session *s = &r->session;
    rig_msg m;
    enum rig_decode_result res = rig_decode(data, len, r->config.key, &m);
    if (res != RIG_DECODED) {
        int old;
        r->counts.malformed++;
        if (res != RIG_E_OTHER_VERSION)
            return 0;
        r->counts.old_version++;
        old = rig_old_hello_version(data, len); /* an old model computer: tell it, in its version, why not */
        if (old == 0 || reply_cap < RIG_V2_BYTES)
            return 0;
        return rig_old_refusal(old, old == 2 ? get_u64(data + 8) : 0, reply);
    }
    rig_expire(r, now_ns);
    if (m.type == RIG_HELLO)
        return hello(r, &m, peer, now_ns, reply, reply_cap);
    if ((m.type != RIG_COMMAND && m.type != RIG_BYE && m.type != RIG_ANSWER) || !s->active) {
        r->counts.unexpected++; /* a command outside a session, or a rig-side message */
        return 0;
    }
    if (!same_peer(peer, &s->owner) || m.session != s->id) {
        r->counts.foreign++; /* never moves the actuator, never ends the session */
        s->counts.foreign++;
        return 0;
    }
    s->last_heard_ns = now_ns;
    if (m.type == RIG_BYE) {
        rig_close(r, "bye");
        return 0;
    }
    if (!finite_msg(&m)) {
        r->counts.nonfinite++;
        s->counts.nonfinite++;
        return 0;
    }
    if ((m.type == RIG_COMMAND || m.type == RIG_ANSWER) && m.u > s->horizon) {
        r->counts.malformed++; /* more heights than the session's horizon */
        return 0;
    }
    if (m.type == RIG_COMMAND && s->pacing == RIG_PACED_BY_MODEL)
        return command(r, &m, reply, reply_cap);
    if (m.type == RIG_ANSWER && s->pacing == RIG_PACED_BY_RIG)
        answer(r, &m, now_ns);
    else
        r->counts.unexpected++;
    return 0;
}
