/**
 * @file main.c
 * @brief Host executable `gainlink_mavlink`: the MAVLink node (gl_mav_node.h) on a UDP link.
 *
 * Usage: `gainlink_mavlink --url udpin:127.0.0.1:14550 [--storage FILE [--from-artifact]] [--signing-key FILE]
 *        [--sysid 1] [--compid 1] [--spin-us N]`
 *
 * What it speaks is the node's (gl_mav_node.h); this file only carries bytes between the UDP socket and
 * the node, keeps the storage file (gl_mav_file.h) and writes the node's events to stderr.
 * - `--spin-us N` (default 0) reads without blocking for N us after each received datagram before
 *   blocking in poll() again: lower lockstep latency for 100 % of a core while spinning.
 * - A new UDP peer gets a HEARTBEAT at once; answers go to the sender of the message they answer.
 * - `--signing-key FILE`: MAVLink 2 signing with the 32-byte key written in FILE as 64 hex digits (see
 *   "Signing" in gl_mav_node.h for what stays open); a SETUP_SIGNING signed with it replaces the key and FILE
 *   (written atomically, mode 0600). UDP is not a trusted link: without a key, SETUP_SIGNING is refused.
 *
 * - `--from-artifact`: start on the compiled set (the artifact's) even when FILE holds a persisted one; FILE is
 *   kept as it is until the next persist.
 *
 * Prints `gainlink-mavlink NAME sha256:HEX n m p q URL` on stdout when ready, then the set in force: ` gains=artifact`
 * (the compiled set of artifact sha256:HEX) or ` gains=persisted` (the set FILE held), ` crc32=DECIMAL
 * format=float32|q31|q15|scheduled-float32`, then the law it runs and the wire format (` law=LAW wire=N`, gl_law.h). Events go to stderr through
 * gl_log.h (rate-limited, never blocking the loop); at exit one summary line accounts for every datagram and
 * frame: `datagrams= dropped= frames= bad_frames= garbage_bytes= unsigned= bad_signature= replayed= ...`.
 */
#define _POSIX_C_SOURCE 200809L
#include <errno.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gl_log.h"
#include "gl_mav_file.h"
#include "gl_mav_key.h"
#include "gl_mav_link.h"
#include "gl_mav_node.h"

/** What the UDP port of the node needs: the link and the sender of the datagram being handled. */
typedef struct udp_port {
    gl_mav_link_t link;
    struct sockaddr_in from;
    const char *storage_path;
    const char *key_path;
    int from_artifact;
} udp_port_t;

static gl_mav_node_t node;
static udp_port_t udp;
static gl_mav_file_t store_file;
static gl_log_t events;
static volatile sig_atomic_t stop;

static void on_signal(int sig)
{
    (void)sig;
    stop = 1;
}

static int udp_send(void *ctx, gl_mav_dest_t dest, const uint8_t *bytes, size_t len)
{
    udp_port_t *u = ctx;
    if (dest == GL_MAV_TO_SENDER) {
        gl_mav_link_send_to(&u->link, bytes, len, &u->from);
    } else {
        gl_mav_link_broadcast(&u->link, bytes, len);
    }
    return 0;
}

static uint64_t now_us(void *ctx)
{
    (void)ctx;
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u;
}

static void link_counters(void *ctx, uint32_t *rx_overruns, uint32_t *tx_dropped)
{
    const udp_port_t *u = ctx;
    *rx_overruns = u->link.rx_dropped;
    *tx_dropped = 0;
}

static int store_key(void *ctx, const uint8_t key[GL_MAV_KEY_LEN])
{
    const udp_port_t *u = ctx;
    return u->key_path == NULL ? 0 : gl_mav_key_write(u->key_path, key);
}

static const char *const refusal_words[] = {
    [GL_MAV_SIG_UNSIGNED] = "unsigned", [GL_MAV_SIG_BAD] = "bad signature",
    [GL_MAV_SIG_REPLAY] = "replayed or too old", [GL_MAV_SIG_STREAMS] = "no free signing stream",
};

/** The node's events as stderr lines, through the rate-limited, non-blocking log. */
static void log_event(void *ctx, gl_mav_event_t ev, int32_t value, uint32_t detail)
{
    const udp_port_t *u = ctx;
    const char *path = u->storage_path != NULL ? u->storage_path : "(no --storage)";
    switch (ev) {
    case GL_MAV_EV_STORE_LOADED:
        gl_log_event(&events, "loaded parameters from %s (crc32 0x%08lx)", path, (unsigned long)(uint32_t)value);
        break;
    case GL_MAV_EV_STORE_IGNORED:
        if (value == GL_MAV_STORE_E_REFUSED) {
            gl_log_event(&events, "ignoring %s: %s (status %ld); using the compiled gain set", path,
                    gl_mav_store_strerror((gl_mav_store_error_t)value), (long)(int32_t)detail);
        } else {
            gl_log_event(&events, "ignoring %s: line %lu: %s; using the compiled gain set", path,
                    (unsigned long)detail, gl_mav_store_strerror((gl_mav_store_error_t)value));
        }
        break;
    case GL_MAV_EV_STORE_UNREADABLE:
        gl_log_event(&events, "cannot reload parameters from %s: %s", path,
                value == 0 ? "nothing stored" : "read error");
        break;
    case GL_MAV_EV_STORE_WRITTEN: gl_log_event(&events, "parameters written to %s", path); break;
    case GL_MAV_EV_STORE_WRITE_FAILED: gl_log_event(&events, "cannot write parameters to %s", path); break;
    case GL_MAV_EV_COMMITTED:
        gl_log_event(&events, "committed gain set crc32 0x%08lx", (unsigned long)(uint32_t)value);
        break;
    case GL_MAV_EV_COMMIT_REFUSED: gl_log_event(&events, "commit refused (status %ld)", (long)value); break;
    case GL_MAV_EV_RESET:
        gl_log_event(&events, "back to the compiled gain set (crc32 0x%08lx)", (unsigned long)(uint32_t)value);
        break;
    case GL_MAV_EV_STAGE_FAILED:
        gl_log_event(&events, "staging the committed set failed (status %ld)", (long)value);
        break;
    case GL_MAV_EV_SIGNATURE_REFUSED:
        gl_log_event(&events, "refused message %lu: %s", (unsigned long)detail,
                (value >= 0 && value <= GL_MAV_SIG_STREAMS) ? refusal_words[value] : "signing");
        break;
    case GL_MAV_EV_PERSIST_LIMITED:
        gl_log_event(&events, "persist refused by the rate limit (next write in %ld s)", (long)value);
        break;
    case GL_MAV_EV_KEY_SET:
        gl_log_event(&events, "signing %s by SETUP_SIGNING", value ? "key replaced" : "turned off");
        break;
    case GL_MAV_EV_SETUP_REFUSED:
        gl_log_event(&events, "SETUP_SIGNING from system %lu refused (unsigned on an untrusted link)",
                (unsigned long)detail);
        break;
    default: break;
    }
}

static int parse_uint(const char *text, unsigned long max, unsigned long *out)
{
    char *end = NULL;
    errno = 0;
    unsigned long v = strtoul(text, &end, 10);
    if (errno != 0 || end == text || *end != '\0' || text[0] == '-' || v > max) {
        return -1;
    }
    *out = v;
    return 0;
}

static int usage(void)
{
    fprintf(stderr, "usage: gainlink_mavlink --url udpin:HOST:PORT|udpout:HOST:PORT [--storage FILE [--from-artifact]] "
                    "[--signing-key FILE] [--sysid N] [--compid N] [--spin-us 0..1000000]\n");
    return 2;
}

/** Feed every waiting datagram to the node; returns 1 when something arrived, -1 on a socket error. */
static int drain_socket(void)
{
    static uint8_t buf[65536];
    long n;
    int got = 0;
    size_t peers_before = udp.link.peers;
    while ((n = gl_mav_link_recv(&udp.link, buf, sizeof buf, &udp.from)) > 0) {
        got = 1;
        gl_mav_node_input(&node, buf, (size_t)n);
        gl_mav_node_resync(&node); /* a frame never spans datagrams */
    }
    if (udp.link.peers != peers_before) {
        gl_mav_node_heartbeat(&node); /* a new peer hears us at once, not up to a second later */
    }
    return n < 0 ? -1 : got;
}

static int serve(unsigned long spin_us)
{
    uint64_t spin_until = 0; /* read without blocking until then (--spin-us after each datagram) */
    while (!stop) {
        gl_log_tick(&events);
        uint64_t next = gl_mav_node_poll(&node);
        uint64_t now = now_us(NULL);
        if (!(spin_us > 0 && now < spin_until)) {
            struct pollfd pfd = {.fd = udp.link.fd, .events = POLLIN, .revents = 0};
            int wait_ms = next > now ? (int)((next - now) / 1000u) + 1 : 0;
            int ready = poll(&pfd, 1, wait_ms > 1000 ? 1000 : wait_ms);
            if (ready < 0 && errno != EINTR) {
                gl_log_always(&events, "poll: %s", strerror(errno));
                return 1;
            }
            if (ready <= 0) {
                continue;
            }
        }
        int got = drain_socket();
        if (got < 0) {
            gl_log_always(&events, "recv: %s", strerror(errno));
            return 1;
        }
        if (got && spin_us > 0) {
            spin_until = now_us(NULL) + spin_us;
        }
    }
    return 0;
}

/** The command line: --url and the numbers; --storage and --signing-key go into the port (udp). */
typedef struct options {
    const char *url;
    unsigned long spin_us;
    unsigned long sysid;
    unsigned long compid;
} options_t;

/** Parse the command line into `opt`; returns 0, or the exit status of a usage error (after saying why). */
static int parse_options(int argc, char **argv, options_t *opt)
{
    *opt = (options_t){.url = NULL, .spin_us = 0, .sysid = 1, .compid = 1};
    for (int i = 1; i < argc; ++i) {
        if (i + 1 < argc && strcmp(argv[i], "--url") == 0) {
            opt->url = argv[++i];
        } else if (i + 1 < argc && strcmp(argv[i], "--storage") == 0) {
            udp.storage_path = argv[++i];
        } else if (strcmp(argv[i], "--from-artifact") == 0) {
            udp.from_artifact = 1;
        } else if (i + 1 < argc && strcmp(argv[i], "--signing-key") == 0) {
            udp.key_path = argv[++i];
        } else if (i + 1 < argc && strcmp(argv[i], "--sysid") == 0) {
            if (parse_uint(argv[++i], 255ul, &opt->sysid) != 0 || opt->sysid == 0) {
                return usage();
            }
        } else if (i + 1 < argc && strcmp(argv[i], "--compid") == 0) {
            if (parse_uint(argv[++i], 255ul, &opt->compid) != 0) {
                return usage();
            }
        } else if (i + 1 < argc && strcmp(argv[i], "--spin-us") == 0) {
            if (parse_uint(argv[++i], 1000000ul, &opt->spin_us) != 0) {
                fprintf(stderr, "gainlink_mavlink: --spin-us must be 0..1000000\n");
                return usage();
            }
        } else {
            return usage();
        }
    }
    return opt->url == NULL ? usage() : 0;
}

/** Start the node on the compiled gain set (and the storage file), keyed with `key` when --signing-key was given,
 * and open the UDP link; returns 0 or the exit status (3: gain set rejected, 2: bad link). */
static int start_node(const options_t *opt, const uint8_t key[GL_MAV_KEY_LEN])
{
    gl_mav_node_config_t cfg = {
        .sysid = (uint8_t)opt->sysid,
        .compid = (uint8_t)opt->compid,
        .chan = 0,
        .watchdog_periods = GL_WATCHDOG_PERIODS_DEFAULT,
        .port = {.ctx = &udp, .send = udp_send, .room = NULL, .now_us = now_us, .event = log_event,
                 .link_counters = link_counters, .store_key = store_key},
        .storage = udp.storage_path != NULL ? gl_mav_file_init(&store_file, udp.storage_path) : NULL,
        .trusted_link = 0,
        .ignore_stored = udp.from_artifact,
    };
    gl_status_t st = gl_mav_node_init(&node, &cfg);
    if (st != GL_OK) {
        fprintf(stderr, "gainlink_mavlink: gain set rejected (status %d)\n", (int)st);
        return 3;
    }
    if (udp.key_path != NULL) {
        gl_mav_node_set_key(&node, key, gl_mav_key_timestamp_now());
    }
    char why[256] = "";
    if (gl_mav_link_open(&udp.link, opt->url, why, sizeof why) != 0) {
        fprintf(stderr, "gainlink_mavlink: %s\n", why);
        return 2;
    }
    return 0;
}

/** SIGTERM and SIGINT end serve() after the message in hand. */
static void catch_stop_signals(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
}

/** The exit line accounting for every datagram and frame (see the file comment). */
static void log_summary(void)
{
    const gl_mav_node_stats_t *n = &node.stats;
    gl_log_always(&events,
                  "datagrams=%llu dropped=%lu frames=%lu bad_frames=%lu garbage_bytes=%lu unsigned=%lu bad_signature=%lu "
                  "replayed=%lu no_stream=%lu setup_refused=%lu samples=%lu refused_sets=%lu commits=%lu "
                  "persist_writes=%lu persist_skipped=%lu persist_limited=%lu crc32=0x%08lx signing=%d "
                  "log_suppressed=%llu log_dropped=%llu",
                  (unsigned long long)udp.link.rx_datagrams, (unsigned long)udp.link.rx_dropped,
                  (unsigned long)n->frames, (unsigned long)n->bad_frames, (unsigned long)gl_mav_node_garbage(&node),
                  (unsigned long)n->sig_unsigned, (unsigned long)n->sig_bad, (unsigned long)n->sig_replay,
                  (unsigned long)n->sig_streams, (unsigned long)n->setup_refused, (unsigned long)n->samples,
                  (unsigned long)n->refused_sets, (unsigned long)n->commits, (unsigned long)n->persist_writes,
                  (unsigned long)n->persist_skipped, (unsigned long)n->persist_limited,
                  (unsigned long)node.table.committed.crc32, node.keyed, (unsigned long long)events.suppressed,
                  (unsigned long long)events.dropped);
}

int main(int argc, char **argv)
{
    options_t opt;
    int rc = parse_options(argc, argv, &opt);
    if (rc != 0) {
        return rc;
    }
    gl_log_init(&events, 2, "gainlink_mavlink", GL_LOG_BURST_DEFAULT);
    uint8_t key[GL_MAV_KEY_LEN] = {0};
    if (udp.key_path != NULL) {
        char why[200];
        if (gl_mav_key_read(udp.key_path, key, why, sizeof why) != 0) {
            fprintf(stderr, "gainlink_mavlink: --signing-key %s: %s\n", udp.key_path, why);
            return 2;
        }
    }
    rc = start_node(&opt, key);
    if (rc != 0) {
        return rc;
    }
    catch_stop_signals();
    printf("gainlink-mavlink %s sha256:%s %d %d %d %d %s gains=%s crc32=%lu format=%s law=%s wire=%d\n",
           gl_artifact_name, gl_artifact_sha256, GL_N, GL_M, GL_P, GL_Q, opt.url,
           node.started_stored ? "persisted" : "artifact", (unsigned long)node.table.committed.crc32, GL_LAW_NAME,
           GL_LAW_NAME, GL_WIRE_VERSION);
    fflush(stdout);
    rc = serve(opt.spin_us);
    log_summary();
    return rc;
}
