/* pantohil_reference_rig: the reference rig on POSIX sockets and the monotonic clock, an ideal
 * actuator carrying a rigid mass (docs/udp-protocol.md; README.md here says what to port).
 *
 *   pantohil_reference_rig --listen HOST:PORT --paced-by model|rig --dt-s S --mass-kg M
 *       [--gravity-m-s2 G] [--key-file F] [--stats FILE] [--max-seconds T] [--session-timeout-s S]
 */
#define _POSIX_C_SOURCE 200809L

#include "rig_link.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netdb.h>
#include <netinet/in.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#define PROGRAM "pantohil_reference_rig"
#define MAX_KEY_FILE_BYTES (64 * 1024)
#define SESSION_LOG_MAX 1024
#define IDLE_WAIT_NS 200000000LL /* with nothing due, look at the clock (session expiry) this often */
#define BURST 64                 /* datagrams handled in a row before the clock is looked at again */

typedef struct options {
    const char *listen, *key_file, *stats;
    int pacing;
    double dt_s, mass_kg, gravity_m_s2, max_seconds, session_timeout_s;
} options;

typedef struct session_record {
    uint64_t number, id;
    char peer[80];
    int pacing;
    rig_counters counts;
    char end[96];
} session_record;

typedef struct program {
    options opt;
    int sock;
    char listen_text[80];
    rig rig;
    rig_rigid_mass mass;
    rig_key key;
    session_record log[SESSION_LOG_MAX];
    size_t log_count;
} program;

static program prog; /* one rig per process; ~100 kB, kept off the stack */
static volatile sig_atomic_t stop_requested;

/* ---- the command line ---- */

static void usage_error(const char *fmt, const char *arg)
{
    fprintf(stderr, PROGRAM ": ");
    fprintf(stderr, fmt, arg);
    fprintf(stderr, " (usage: " PROGRAM " --listen HOST:PORT --paced-by model|rig --dt-s S --mass-kg M"
                    " [--gravity-m-s2 G] [--key-file F] [--stats FILE] [--max-seconds T]"
                    " [--session-timeout-s S])\n");
    exit(2);
}

static double number_arg(const char *name, const char *text)
{
    char *end;
    double v;
    errno = 0;
    v = strtod(text, &end);
    if (end == text || *end != '\0' || errno == ERANGE || !isfinite(v))
        usage_error("%s: expected a finite number", name);
    return v;
}

static void parse_options(int argc, char **argv, options *o)
{
    int i, have_pacing = 0;
    memset(o, 0, sizeof *o);
    o->dt_s = o->mass_kg = NAN;
    o->session_timeout_s = 5.0;
    for (i = 1; i < argc; i++) {
        const char *name = argv[i], *value = i + 1 < argc ? argv[i + 1] : NULL;
        if (strncmp(name, "--", 2) != 0)
            usage_error("unexpected argument %s", name);
        if (value == NULL)
            usage_error("%s: a value is missing", name);
        i++;
        if (strcmp(name, "--listen") == 0) {
            o->listen = value;
        } else if (strcmp(name, "--paced-by") == 0) {
            if (strcmp(value, "model") != 0 && strcmp(value, "rig") != 0)
                usage_error("--paced-by: must be model or rig (got %s)", value);
            o->pacing = strcmp(value, "rig") == 0 ? RIG_PACED_BY_RIG : RIG_PACED_BY_MODEL;
            have_pacing = 1;
        } else if (strcmp(name, "--dt-s") == 0) {
            o->dt_s = number_arg(name, value);
        } else if (strcmp(name, "--mass-kg") == 0) {
            o->mass_kg = number_arg(name, value);
        } else if (strcmp(name, "--gravity-m-s2") == 0) {
            o->gravity_m_s2 = number_arg(name, value);
        } else if (strcmp(name, "--key-file") == 0) {
            o->key_file = value;
        } else if (strcmp(name, "--stats") == 0) {
            o->stats = value;
        } else if (strcmp(name, "--max-seconds") == 0) {
            o->max_seconds = number_arg(name, value);
            if (o->max_seconds <= 0)
                usage_error("%s: must be above 0", name);
        } else if (strcmp(name, "--session-timeout-s") == 0) {
            o->session_timeout_s = number_arg(name, value);
            if (o->session_timeout_s <= 0 || o->session_timeout_s > 1e6)
                usage_error("%s: must be in (0, 1e6] s", name);
        } else {
            usage_error("unknown option %s", name);
        }
    }
    if (o->listen == NULL)
        usage_error("%s is required", "--listen HOST:PORT");
    if (!have_pacing)
        usage_error("%s is required", "--paced-by model|rig");
    if (isnan(o->dt_s) || o->dt_s < RIG_MIN_DT_S || o->dt_s > RIG_MAX_DT_S)
        usage_error("%s: required, in [1e-05, 1] s", "--dt-s");
    if (isnan(o->mass_kg) || o->mass_kg <= 0)
        usage_error("%s: required, above 0 kg", "--mass-kg");
}

/* ---- the socket ---- */

static int open_socket(const char *listen_text)
{
    char host[256];
    const char *colon = strrchr(listen_text, ':'), *port;
    size_t host_len;
    struct addrinfo hints, *found, *ai;
    int fd = -1, rcvbuf = 4 << 20;
    if (colon == NULL || colon == listen_text || colon[1] == '\0')
        usage_error("--listen: expected HOST:PORT, got %s", listen_text);
    port = colon + 1;
    host_len = (size_t)(colon - listen_text);
    if (listen_text[0] == '[' && host_len >= 2 && listen_text[host_len - 1] == ']') { /* [::1]:PORT */
        listen_text++;
        host_len -= 2;
    }
    if (host_len >= sizeof host || strspn(port, "0123456789") != strlen(port) || atol(port) > 65535)
        usage_error("--listen: expected HOST:PORT, got %s", listen_text);
    memcpy(host, listen_text, host_len);
    host[host_len] = '\0';
    memset(&hints, 0, sizeof hints);
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_DGRAM;
    hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
    if (getaddrinfo(host, port, &hints, &found) != 0)
        usage_error("--listen: cannot resolve the host of %s", listen_text);
    for (ai = found; ai != NULL && fd < 0; ai = ai->ai_next) {
        fd = socket(ai->ai_family, ai->ai_socktype, ai->ai_protocol);
        if (fd >= 0 && bind(fd, ai->ai_addr, ai->ai_addrlen) != 0) {
            close(fd);
            fd = -1;
        }
    }
    freeaddrinfo(found);
    if (fd < 0)
        usage_error("--listen: cannot bind %s", listen_text);
    setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
    fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) | O_NONBLOCK);
    return fd;
}

static void address_text(const struct sockaddr *sa, socklen_t len, char *out, size_t cap)
{
    char host[64], port[16];
    if (getnameinfo(sa, len, host, sizeof host, port, sizeof port, NI_NUMERICHOST | NI_NUMERICSERV) != 0) {
        snprintf(out, cap, "?");
        return;
    }
    snprintf(out, cap, sa->sa_family == AF_INET6 ? "[%s]:%s" : "%s:%s", host, port);
}

/* The sender as the rig's opaque peer: a zeroed address of its family with only address and port set,
 * so two datagrams from one socket compare equal byte for byte. */
static void to_peer(const struct sockaddr_storage *from, rig_peer *peer)
{
    memset(peer, 0, sizeof *peer);
    if (from->ss_family == AF_INET6) {
        struct sockaddr_in6 a, src;
        memcpy(&src, from, sizeof src);
        memset(&a, 0, sizeof a);
        a.sin6_family = AF_INET6;
        a.sin6_port = src.sin6_port;
        a.sin6_addr = src.sin6_addr;
        a.sin6_scope_id = src.sin6_scope_id;
        memcpy(peer->bytes, &a, sizeof a);
        peer->len = sizeof a;
    } else {
        struct sockaddr_in a, src;
        memcpy(&src, from, sizeof src);
        memset(&a, 0, sizeof a);
        a.sin_family = AF_INET;
        a.sin_port = src.sin_port;
        a.sin_addr = src.sin_addr;
        memcpy(peer->bytes, &a, sizeof a);
        peer->len = sizeof a;
    }
}

static void send_to_peer(int fd, const uint8_t *data, size_t len, const rig_peer *peer)
{
    struct sockaddr_storage to;
    memset(&to, 0, sizeof to);
    memcpy(&to, peer->bytes, peer->len);
    (void)sendto(fd, data, len, 0, (const struct sockaddr *)&to, (socklen_t)peer->len);
}

static void peer_text(const rig_peer *peer, char *out, size_t cap)
{
    struct sockaddr_storage a;
    memset(&a, 0, sizeof a);
    memcpy(&a, peer->bytes, peer->len);
    address_text((const struct sockaddr *)&a, (socklen_t)peer->len, out, cap);
}

/* ---- the key file (docs/udp-protocol.md, "Authentication") ---- */

static int is_space(uint8_t c)
{
    return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f';
}

static void read_key(const char *path, rig_key *key)
{
    static uint8_t buf[MAX_KEY_FILE_BYTES + 1];
    struct stat st;
    size_t len = 0, start = 0;
    ssize_t got;
    int fd = open(path, O_RDONLY | O_NONBLOCK);
    if (fd < 0 || fstat(fd, &st) != 0 || !S_ISREG(st.st_mode))
        usage_error("--key-file %s: not a readable regular file", path);
    while ((got = read(fd, buf + len, sizeof buf - len)) > 0 && len + (size_t)got < sizeof buf)
        len += (size_t)got;
    if (got > 0)
        len += (size_t)got;
    close(fd);
    if (got < 0 || len > MAX_KEY_FILE_BYTES)
        usage_error("--key-file %s: unreadable, or larger than 64 KiB", path);
    while (start < len && is_space(buf[start]))
        start++;
    while (len > start && is_space(buf[len - 1]))
        len--;
    if (len - start < 16 || len - start > 4096)
        usage_error("key file %s: the key must have 16 to 4096 bytes", path);
    rig_key_init(key, buf + start, len - start);
    memset(buf, 0, sizeof buf);
}

/* ---- the stats file ---- */

static void write_counters(FILE *f, const rig_counters *c)
{
    fprintf(f, "\"sessions\": %llu, \"commands\": %llu, \"answers\": %llu, \"samples\": %llu, \"answered\": %llu, "
               "\"malformed\": %llu, \"old_version\": %llu, \"unexpected\": %llu, \"foreign\": %llu, "
               "\"nonfinite\": %llu, \"bad_hello\": %llu, \"replayed\": %llu, \"doubled\": %llu, "
               "\"fresh\": %llu, \"predicted\": %llu, \"uncovered\": %llu, \"max_abs_height_m\": %.17g",
            (unsigned long long)c->sessions, (unsigned long long)c->commands, (unsigned long long)c->answers,
            (unsigned long long)c->samples, (unsigned long long)c->answered, (unsigned long long)c->malformed,
            (unsigned long long)c->old_version, (unsigned long long)c->unexpected,
            (unsigned long long)c->foreign, (unsigned long long)c->nonfinite, (unsigned long long)c->bad_hello,
            (unsigned long long)c->replayed, (unsigned long long)c->doubled, (unsigned long long)c->fresh,
            (unsigned long long)c->predicted, (unsigned long long)c->uncovered, c->max_abs_height_m);
}

static void write_session(FILE *f, const session_record *s)
{
    fprintf(f, "  {\"number\": %llu, \"peer\": \"%s\", \"id\": \"%016llx\", \"paced_by\": \"%s\", ",
            (unsigned long long)s->number, s->peer, (unsigned long long)s->id,
            s->pacing == RIG_PACED_BY_RIG ? "rig" : "model");
    write_counters(f, &s->counts);
    fprintf(f, ", \"end\": \"%s\"}", s->end);
}

/* Written to FILE.tmp and renamed: a reader never sees half a file. */
static void write_stats(const program *p)
{
    char tmp[4096];
    FILE *f;
    size_t i;
    if (p->opt.stats == NULL)
        return;
    snprintf(tmp, sizeof tmp, "%s.tmp", p->opt.stats);
    f = fopen(tmp, "w");
    if (f == NULL)
        return;
    fprintf(f, "{\"listen\": \"%s\", \"paced_by\": \"%s\", \"dt_s\": %.17g, \"mass_kg\": %.17g, "
               "\"gravity_m_s2\": %.17g,\n ",
            p->listen_text, p->opt.pacing == RIG_PACED_BY_RIG ? "rig" : "model", p->opt.dt_s, p->opt.mass_kg,
            p->opt.gravity_m_s2);
    write_counters(f, &p->rig.counts);
    fprintf(f, ",\n \"session_log\": [");
    for (i = 0; i < p->log_count; i++) {
        fprintf(f, i ? ",\n" : "\n");
        write_session(f, &p->log[i]);
    }
    fprintf(f, "]}\n");
    if (fclose(f) == 0)
        rename(tmp, p->opt.stats);
}

/* ---- sessions ---- */

static void on_event(void *ctx, const rig *r, enum rig_event e, const char *why)
{
    program *p = ctx;
    const rig_session *s = &r->session;
    char peer[80];
    peer_text(&s->owner, peer, sizeof peer);
    if (e == RIG_SESSION_OPENED) {
        printf("session %llu opened by %s (%s-paced, dt %g s, horizon %u)\n", (unsigned long long)s->number, peer,
               s->pacing == RIG_PACED_BY_RIG ? "rig" : "model", s->dt_s, s->horizon);
        return;
    }
    printf("session %llu closed (%s): %llu commands, fresh %llu predicted %llu uncovered %llu, %llu foreign "
           "datagrams refused\n",
           (unsigned long long)s->number, why, (unsigned long long)s->counts.commands,
           (unsigned long long)s->counts.fresh, (unsigned long long)s->counts.predicted,
           (unsigned long long)s->counts.uncovered, (unsigned long long)s->counts.foreign);
    if (p->log_count < SESSION_LOG_MAX) {
        session_record *rec = &p->log[p->log_count++];
        rec->number = s->number;
        rec->id = s->id;
        rec->pacing = s->pacing;
        rec->counts = s->counts;
        snprintf(rec->peer, sizeof rec->peer, "%s", peer);
        snprintf(rec->end, sizeof rec->end, "%s", why);
    }
    write_stats(p);
}

/* ---- the loop ---- */

static int64_t monotonic_ns(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (int64_t)t.tv_sec * 1000000000LL + t.tv_nsec;
}

static void request_stop(int signum)
{
    (void)signum;
    stop_requested = 1;
}

static void receive_burst(program *p)
{
    uint8_t data[2048], reply[RIG_MAX_DATAGRAM];
    int i;
    for (i = 0; i < BURST; i++) {
        struct sockaddr_storage from;
        socklen_t from_len = sizeof from;
        rig_peer peer;
        size_t n;
        ssize_t got = recvfrom(p->sock, data, sizeof data, 0, (struct sockaddr *)&from, &from_len);
        if (got < 0)
            return; /* nothing more waiting, or an ICMP error on the socket */
        to_peer(&from, &peer);
        n = rig_handle_datagram(&p->rig, data, (size_t)got, &peer, monotonic_ns(), reply, sizeof reply);
        if (n)
            send_to_peer(p->sock, reply, n, &peer);
    }
}

/* Wait for a datagram until wake_ns (monotonic) at most; the signals that stop the rig are let in
 * only here, so a stop is never missed between the check and the wait. */
static int wait_readable(int fd, int64_t wait_ns, const sigset_t *wait_mask)
{
    fd_set readable;
    struct timespec timeout;
    if (wait_ns < 0)
        wait_ns = 0;
    timeout.tv_sec = (time_t)(wait_ns / 1000000000LL);
    timeout.tv_nsec = (long)(wait_ns % 1000000000LL);
    FD_ZERO(&readable);
    FD_SET(fd, &readable);
    return pselect(fd + 1, &readable, NULL, NULL, &timeout, wait_mask) > 0;
}

static void serve(program *p, const sigset_t *wait_mask)
{
    uint8_t sample[RIG_MAX_DATAGRAM];
    int64_t end_ns = p->opt.max_seconds > 0 ? monotonic_ns() + (int64_t)(p->opt.max_seconds * 1e9) : INT64_MAX;
    while (!stop_requested) {
        int64_t now = monotonic_ns(), due = rig_next_tick_ns(&p->rig), wake = now + IDLE_WAIT_NS;
        if (now >= end_ns)
            break;
        if (due >= 0 && now >= due) {
            size_t n = rig_tick(&p->rig, now, sample, sizeof sample);
            if (n)
                send_to_peer(p->sock, sample, n, rig_owner(&p->rig));
            wake = now; /* then take what is waiting, without sleeping */
        } else if (due >= 0 && due < wake) {
            wake = due;
        }
        if (end_ns < wake)
            wake = end_ns;
        if (wait_readable(p->sock, wake - now, wait_mask))
            receive_burst(p);
        rig_expire(&p->rig, monotonic_ns());
    }
}

int main(int argc, char **argv)
{
    program *p = &prog;
    rig_config config;
    struct sigaction action;
    sigset_t stop_signals, wait_mask;
    struct sockaddr_storage bound;
    socklen_t bound_len = sizeof bound;

    parse_options(argc, argv, &p->opt);
    if (p->opt.key_file)
        read_key(p->opt.key_file, &p->key);
    p->sock = open_socket(p->opt.listen);
    getsockname(p->sock, (struct sockaddr *)&bound, &bound_len);
    address_text((const struct sockaddr *)&bound, bound_len, p->listen_text, sizeof p->listen_text);

    rig_rigid_mass_init(&p->mass, p->opt.mass_kg, p->opt.gravity_m_s2, p->opt.dt_s);
    memset(&config, 0, sizeof config);
    config.pacing = p->opt.pacing;
    config.dt_s = p->opt.dt_s;
    config.latency_steps = 0; /* the ideal actuator */
    config.max_horizon = RIG_MAX_HORIZON;
    config.session_timeout_ns = (int64_t)(p->opt.session_timeout_s * 1e9);
    config.key = p->opt.key_file ? &p->key : NULL;
    config.physics = rig_rigid_mass_physics(&p->mass);
    config.on_event = on_event;
    config.event_ctx = p;
    rig_init(&p->rig, &config);

    sigemptyset(&stop_signals);
    sigaddset(&stop_signals, SIGINT);
    sigaddset(&stop_signals, SIGTERM);
    sigprocmask(SIG_BLOCK, &stop_signals, &wait_mask);
    sigdelset(&wait_mask, SIGINT);
    sigdelset(&wait_mask, SIGTERM);
    memset(&action, 0, sizeof action);
    action.sa_handler = request_stop;
    sigemptyset(&action.sa_mask);
    sigaction(SIGINT, &action, NULL);
    sigaction(SIGTERM, &action, NULL);

    setvbuf(stdout, NULL, _IOLBF, 0);
    printf(PROGRAM " listening on %s (%s-paced, dt %g s, rigid mass %g kg, gravity %g m/s2%s)\n", p->listen_text,
           p->opt.pacing == RIG_PACED_BY_RIG ? "rig" : "model", p->opt.dt_s, p->opt.mass_kg, p->opt.gravity_m_s2,
           p->opt.key_file ? ", HMAC key" : "");
    serve(p, &wait_mask);
    rig_close(&p->rig, stop_requested ? "rig stopped by a signal" : "rig stopped: --max-seconds");
    write_stats(p);
    close(p->sock);
    return 0;
}
