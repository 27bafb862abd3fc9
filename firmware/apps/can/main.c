/**
 * @file main.c
 * @brief `gainlink_can`: the control loop as a CAN node, for HIL runs (`gainlink firmware run --can`, `gainlink hil run`).
 *
 * Usage:
 * @code
 *   gainlink_can --backend udp --channel 239.74.163.2 [--port 43113] [--reply-port N] [--hop-limit 0] [--fd]
 *                [--base-id 256]
 *   gainlink_can --backend socketcan --channel vcan0 [--fd] [--base-id 256]
 *   gainlink_can ... --encoding int16 --scale-measurement 'F,O;F,O;F,O' --scale-command 'F,O'
 * @endcode
 * `--reply-port N` (udp) sends the commands to port N of the group instead of `--port`, where the samples come:
 * neither end then reads back its own frames (python-can's bus pays for every datagram it hears).
 * `--spin-us N` polls without sleeping for N us after each answered sample before blocking again
 * (lower latency in lockstep for the price of a busy core while waiting).
 * `--encoding float32|int16` (default float32): with int16 every value is a scaled signed 16-bit integer,
 * `physical = raw * factor + offset`; `--scale-measurement` gives the `factor,offset` pairs of the
 * sample (GL_P outputs then GL_Q references) and `--scale-command` those of the command (GL_M inputs),
 * pairs separated by `;`, exactly as many as values (gainlink.hil.links.can.firmware_can_argv writes
 * them from the DBC's numbers). A non-finite value travels as raw -32768 and decodes to NaN, so the loop's
 * fault path still answers it; commands beyond their range saturate to it (counted: `clipped=` at exit).
 * The node itself (sample assembly by sequence number, step, command frames) is gl_can_node.h, shared with
 * the Cortex-M4F image's slcan port; this file parses the options and carries frames between the link and
 * the node. Prints
 * one `gainlink_can ready ...` line on stdout once the link is open; SIGTERM/SIGINT end it (exit 0).
 *
 * Events (a refused datagram, a short frame, a failed send) go to stderr through gl_log.h: at most
 * GL_LOG_BURST_DEFAULT lines a second plus a count of the rest, and never a write that could block the loop.
 * The exit summary accounts for every datagram read: `read = used + short + filtered + refused` (`used`:
 * measurement frames decoded, of which `stale` were older than the last answered sample; samples dropped
 * half-assembled are counted in `partial_dropped`), and `dropped` is what the kernel dropped before the app
 * read it (known at the next datagram read).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gl_can_layout.h"
#include "gl_can_link.h"
#include "gl_can_node.h"
#include "gl_log.h"

#define N_SAMPLE GL_CAN_NODE_SAMPLE

static volatile sig_atomic_t stop_requested;
static gl_can_node_t node;
static gl_can_node_config_t node_cfg;
static gl_can_link_t can_link;
static gl_log_t events;

static int send_frame(void *ctx, const gl_can_frame_t *frame)
{
    return gl_can_link_send(ctx, frame);
}

static void log_event(void *ctx, gl_can_node_event_t ev, const gl_can_frame_t *frame)
{
    (void)ctx;
    if (ev == GL_CAN_EV_SHORT_FRAME) {
        gl_log_event(&events, "frame 0x%03x of %u bytes is too short for its values", (unsigned)frame->id,
                     (unsigned)frame->len);
    } else if (ev == GL_CAN_EV_SEND_FAILED) {
        gl_log_event(&events, "sending command frame 0x%03x failed: %s", (unsigned)frame->id, strerror(errno));
    }
}

static void on_signal(int sig)
{
    (void)sig;
    stop_requested = 1;
}

static int usage(const char *why)
{
    fprintf(stderr, "gainlink_can: %s (gainlink_can --help lists the options)\n", why);
    return 2;
}

static int help(void)
{
    printf("usage: gainlink_can --backend udp|socketcan --channel GROUP|IFACE [--port N] [--reply-port N]\n"
           "                    [--hop-limit N] [--fd] [--base-id N] [--spin-us N]\n"
           "                    [--encoding float32|int16 --scale-measurement F,O;F,O;... --scale-command F,O;...]\n"
           "\n"
           "  --backend udp|socketcan  python-can udp_multicast wire format, or a SocketCAN interface\n"
           "  --channel GROUP|IFACE    IPv4 multicast group (udp) or interface name (socketcan)\n"
           "  --port N, --hop-limit N  udp_multicast port (default 43113) and TTL (default 1; 0 stays on the host)\n"
           "  --reply-port N           udp_multicast: send the commands to this port (default: --port)\n"
           "  --fd                     CAN FD frames (up to 8 values per frame)\n"
           "  --base-id N              first 11-bit identifier (default 0x100; commands base+j, samples base+0x10+i)\n"
           "  --spin-us N              poll without sleeping for N us after each answer (default 0)\n"
           "  --encoding E             float32 (default): IEEE float32 values; int16: scaled integers,\n"
           "                           physical = raw * factor + offset, raw -32767..32767 (beyond: saturated),\n"
           "                           raw -32768 = not a number; 2 values per classic frame\n"
           "  --scale-measurement S    int16: factor,offset of each sample value (%d outputs then %d references),\n"
           "                           pairs separated by ';'\n"
           "  --scale-command S        int16: factor,offset of each command value (%d inputs)\n"
           "\n"
           "gainlink writes these arguments from the artifact's DBC (gainlink hil dbc; gainlink firmware run --can).\n",
           GL_P, GL_Q, GL_M);
    return 0;
}

static uint64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

static int parse_uint(const char *text, unsigned long max, unsigned long *out)
{
    char *end = NULL;
    errno = 0;
    unsigned long v = strtoul(text, &end, 0);
    if (errno != 0 || end == text || *end != '\0' || v > max) {
        return -1;
    }
    *out = v;
    return 0;
}

/**
 * Parse exactly `count` `factor,offset` pairs separated by `;` (factor finite and > 0, offset finite).
 * Returns 0, or -1 with a reason in `why`.
 */
static int parse_scales(const char *text, gl_can_scale_t *scales, uint32_t count, char *why, size_t why_len)
{
    const char *p = text;
    for (uint32_t i = 0; i < count; ++i) {
        char *end = NULL;
        errno = 0;
        double f = strtod(p, &end);
        if (end == p || *end != ',' || errno != 0 || !isfinite(f) || !(f > 0.0)) {
            snprintf(why, why_len, "pair %u: factor must be a finite number > 0", (unsigned)(i + 1u));
            return -1;
        }
        p = end + 1;
        double o = strtod(p, &end);
        if (end == p || errno != 0 || !isfinite(o)) {
            snprintf(why, why_len, "pair %u: offset must be a finite number", (unsigned)(i + 1u));
            return -1;
        }
        scales[i].factor = f;
        scales[i].offset = o;
        p = end;
        if (i + 1u < count) {
            if (*p != ';') {
                snprintf(why, why_len, "expected %u factor,offset pairs separated by ';', got %u", (unsigned)count,
                         (unsigned)(i + 1u));
                return -1;
            }
            ++p;
        }
    }
    if (*p != '\0') {
        snprintf(why, why_len, "expected %u factor,offset pairs separated by ';', got more or trailing text",
                 (unsigned)count);
        return -1;
    }
    return 0;
}

/** What the command line asks for. */
typedef struct {
    gl_can_config_t link;
    unsigned long base_id;
    unsigned long spin_us;
    gl_can_encoding_t encoding;
    const char *scale_meas;
    const char *scale_cmd;
} options_t;

/** One option that takes a value (`next`); 0, or the exit status of the usage error. */
static int parse_value_option(const char *a, const char *next, options_t *o)
{
    unsigned long v = 0;
    if (strcmp(a, "--backend") == 0) {
        if (strcmp(next, "udp") != 0 && strcmp(next, "socketcan") != 0) {
            return usage("--backend must be udp or socketcan");
        }
        o->link.backend = strcmp(next, "udp") == 0 ? GL_CAN_UDP : GL_CAN_SOCKETCAN;
    } else if (strcmp(a, "--channel") == 0) {
        o->link.channel = next;
    } else if (strcmp(a, "--port") == 0) {
        if (parse_uint(next, 65535, &v) != 0) {
            return usage("--port must be 0..65535");
        }
        o->link.port = (uint16_t)v;
    } else if (strcmp(a, "--reply-port") == 0) {
        if (parse_uint(next, 65535, &v) != 0 || v == 0u) {
            return usage("--reply-port must be 1..65535");
        }
        o->link.reply_port = (uint16_t)v;
    } else if (strcmp(a, "--hop-limit") == 0) {
        if (parse_uint(next, 255, &v) != 0) {
            return usage("--hop-limit must be 0..255");
        }
        o->link.hop_limit = (int)v;
    } else if (strcmp(a, "--spin-us") == 0) {
        if (parse_uint(next, 1000000, &o->spin_us) != 0) {
            return usage("--spin-us must be 0..1000000");
        }
    } else if (strcmp(a, "--encoding") == 0) {
        if (strcmp(next, "float32") != 0 && strcmp(next, "int16") != 0) {
            return usage("--encoding must be float32 or int16");
        }
        o->encoding = strcmp(next, "int16") == 0 ? GL_CAN_INT16 : GL_CAN_FLOAT32;
    } else if (strcmp(a, "--scale-measurement") == 0) {
        o->scale_meas = next;
    } else if (strcmp(a, "--scale-command") == 0) {
        o->scale_cmd = next;
    } else if (strcmp(a, "--base-id") == 0) {
        if (parse_uint(next, 0x7FF - 0x30, &o->base_id) != 0) {
            return usage("--base-id must leave room for the layout (0..0x7cf)");
        }
    } else {
        return usage("unknown option");
    }
    return 0;
}

/** The whole command line; 0, -1 after --help (exit 0), or the exit status of the usage error. */
static int parse_options(int argc, char **argv, options_t *o)
{
    for (int i = 1; i < argc; ++i) {
        const char *a = argv[i];
        const char *next = i + 1 < argc ? argv[i + 1] : NULL;
        if (strcmp(a, "--help") == 0 || strcmp(a, "-h") == 0) {
            (void)help();
            return -1;
        }
        if (strcmp(a, "--fd") == 0) {
            o->link.fd = 1;
            continue;
        }
        if (next == NULL) {
            return usage("missing value or unknown option");
        }
        int rc = parse_value_option(a, next, o);
        if (rc != 0) {
            return rc;
        }
        ++i;
    }
    return o->link.channel == NULL ? usage("--channel is required") : 0;
}

/** The int16 scales into the node's configuration (both lists required with int16, refused without). */
static int configure_encoding(const options_t *o)
{
    if (o->encoding != GL_CAN_INT16) {
        return (o->scale_meas != NULL || o->scale_cmd != NULL)
                   ? usage("--scale-measurement and --scale-command need --encoding int16")
                   : 0;
    }
    char why[160], msg[240];
    if (o->scale_meas == NULL || o->scale_cmd == NULL) {
        return usage("--encoding int16 needs --scale-measurement and --scale-command");
    }
    if (parse_scales(o->scale_meas, node_cfg.meas_scale, N_SAMPLE, why, sizeof why) != 0) {
        snprintf(msg, sizeof msg, "--scale-measurement (%u values: outputs then references): %s",
                 (unsigned)N_SAMPLE, why);
        return usage(msg);
    }
    if (parse_scales(o->scale_cmd, node_cfg.cmd_scale, GL_M, why, sizeof why) != 0) {
        snprintf(msg, sizeof msg, "--scale-command (%u values): %s", (unsigned)GL_M, why);
        return usage(msg);
    }
    return 0;
}

static void install_signals(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
}

/** Frames from the link into the node until SIGTERM/SIGINT (0) or a receive error (1). */
static int serve(unsigned long spin_us)
{
    uint64_t refused_seen = 0;
    uint64_t spin_until = 0;
    while (!stop_requested) {
        gl_can_frame_t frame;
        int r = gl_can_link_recv(&can_link, &frame, (spin_us > 0 && now_ns() < spin_until) ? 0 : 200);
        if (can_link.rx_refused != refused_seen) {
            gl_log_event(&events, "refused %llu datagram(s) that are not standard CAN data frames",
                         (unsigned long long)(can_link.rx_refused - refused_seen));
            refused_seen = can_link.rx_refused;
        }
        gl_log_tick(&events);
        if (r < 0) {
            gl_log_always(&events, "receive failed: %s", strerror(errno));
            return 1;
        }
        if (r > 0 && gl_can_node_frame(&node, &frame)) {
            spin_until = now_ns() + 1000ull * spin_us;
        }
    }
    return 0;
}

static void print_summary(void)
{
    const gl_can_node_stats_t *n = &node.stats;
    gl_log_always(&events,
                  "steps=%lu stale=%lu partial_dropped=%lu send_errors=%lu filtered=%llu clipped=%lu read=%llu "
                  "used=%lu short=%lu refused=%llu dropped=%llu log_suppressed=%llu log_dropped=%llu",
                  (unsigned long)n->steps, (unsigned long)n->stale, (unsigned long)n->partial_dropped,
                  (unsigned long)n->send_errors, (unsigned long long)(can_link.rx_filtered + n->foreign),
                  (unsigned long)n->clipped, (unsigned long long)can_link.rx_read, (unsigned long)n->used,
                  (unsigned long)n->short_frames, (unsigned long long)can_link.rx_refused,
                  (unsigned long long)can_link.rx_dropped, (unsigned long long)events.suppressed,
                  (unsigned long long)events.dropped);
}

int main(int argc, char **argv)
{
    options_t o = {.link = {.backend = GL_CAN_UDP, .channel = NULL, .port = 43113, .reply_port = 0, .hop_limit = 1,
                            .fd = 0, .rx_lo = 0, .rx_hi = 0},
                   .base_id = 0x100, .spin_us = 0, .encoding = GL_CAN_FLOAT32, .scale_meas = NULL,
                   .scale_cmd = NULL};
    int rc = parse_options(argc, argv, &o);
    if (rc != 0) {
        return rc < 0 ? 0 : rc;
    }
    rc = configure_encoding(&o);
    if (rc != 0) {
        return rc;
    }
    node_cfg.base_id = (uint32_t)o.base_id;
    node_cfg.fd = o.link.fd;
    node_cfg.encoding = o.encoding;
    node_cfg.watchdog_periods = GL_WATCHDOG_PERIODS_DEFAULT;
    node_cfg.ctx = &can_link;
    node_cfg.send = send_frame;
    node_cfg.event = log_event;
    gl_status_t st = gl_can_node_init(&node, &node_cfg);
    if (st != GL_OK) {
        fprintf(stderr, "gainlink_can: built-in gains rejected (status %d)\n", (int)st);
        return 3;
    }
    gl_can_node_rx_range(&node, &o.link.rx_lo, &o.link.rx_hi);
    install_signals();
    gl_log_init(&events, 2, "gainlink_can", GL_LOG_BURST_DEFAULT);
    if (gl_can_link_open(&can_link, &o.link) != 0) {
        return 4;
    }
    printf("gainlink_can ready %s sha256:%s n=%d m=%d p=%d q=%d fd=%d base_id=%lu encoding=%s law=%s wire=%d\n",
           gl_artifact_name, gl_artifact_sha256, GL_N, GL_M, GL_P, GL_Q, o.link.fd, o.base_id,
           o.encoding == GL_CAN_INT16 ? "int16" : "float32", GL_LAW_NAME, GL_WIRE_VERSION);
    fflush(stdout);
    rc = serve(o.spin_us);
    gl_can_link_close(&can_link);
    print_summary();
    return rc;
}
