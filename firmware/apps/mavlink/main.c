/**
 * @file main.c
 * @brief Host executable `gainlink_mavlink`: the MAVLink node (gl_mav_node.h) on a UDP link.
 *
 * Usage: `gainlink_mavlink --url udpin:127.0.0.1:14550 [--storage FILE] [--sysid 1] [--compid 1] [--spin-us N]`
 *
 * What it speaks is the node's (gl_mav_node.h); this file only carries bytes between the UDP socket and
 * the node, keeps the storage file (gl_mav_file.h) and writes the node's events to stderr.
 * - `--spin-us N` (default 0) reads without blocking for N us after each received datagram before
 *   blocking in poll() again: lower lockstep latency for 100 % of a core while spinning.
 * - A new UDP peer gets a HEARTBEAT at once; answers go to the sender of the message they answer.
 *
 * Prints `gainlink-mavlink NAME sha256:HEX n m p q URL` on stdout when ready; events go to stderr.
 */
#define _POSIX_C_SOURCE 200809L
#include <errno.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gainlink/gl_loop.h"
#include "gl_mav_file.h"
#include "gl_mav_link.h"
#include "gl_mav_node.h"

/** What the UDP port of the node needs: the link and the sender of the datagram being handled. */
typedef struct udp_port {
    gl_mav_link_t link;
    struct sockaddr_in from;
    const char *storage_path;
} udp_port_t;

static gl_mav_node_t node;
static udp_port_t udp;
static gl_mav_file_t store_file;
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

/** The node's events as one stderr line each. */
static void log_event(void *ctx, gl_mav_event_t ev, int32_t value, uint32_t detail)
{
    const udp_port_t *u = ctx;
    const char *path = u->storage_path != NULL ? u->storage_path : "(no --storage)";
    switch (ev) {
    case GL_MAV_EV_STORE_LOADED:
        fprintf(stderr, "gainlink_mavlink: loaded parameters from %s (crc32 0x%08lx)\n", path, (unsigned long)(uint32_t)value);
        break;
    case GL_MAV_EV_STORE_IGNORED:
        if (value == GL_MAV_STORE_E_REFUSED) {
            fprintf(stderr, "gainlink_mavlink: ignoring %s: %s (status %ld); using the compiled gain set\n", path,
                    gl_mav_store_strerror((gl_mav_store_error_t)value), (long)(int32_t)detail);
        } else {
            fprintf(stderr, "gainlink_mavlink: ignoring %s: line %lu: %s; using the compiled gain set\n", path,
                    (unsigned long)detail, gl_mav_store_strerror((gl_mav_store_error_t)value));
        }
        break;
    case GL_MAV_EV_STORE_UNREADABLE:
        fprintf(stderr, "gainlink_mavlink: cannot reload parameters from %s: %s\n", path,
                value == 0 ? "nothing stored" : "read error");
        break;
    case GL_MAV_EV_STORE_WRITTEN: fprintf(stderr, "gainlink_mavlink: parameters written to %s\n", path); break;
    case GL_MAV_EV_STORE_WRITE_FAILED: fprintf(stderr, "gainlink_mavlink: cannot write parameters to %s\n", path); break;
    case GL_MAV_EV_COMMITTED:
        fprintf(stderr, "gainlink_mavlink: committed gain set crc32 0x%08lx\n", (unsigned long)(uint32_t)value);
        break;
    case GL_MAV_EV_COMMIT_REFUSED: fprintf(stderr, "gainlink_mavlink: commit refused (status %ld)\n", (long)value); break;
    case GL_MAV_EV_RESET:
        fprintf(stderr, "gainlink_mavlink: back to the compiled gain set (crc32 0x%08lx)\n", (unsigned long)(uint32_t)value);
        break;
    case GL_MAV_EV_STAGE_FAILED:
        fprintf(stderr, "gainlink_mavlink: staging the committed set failed (status %ld)\n", (long)value);
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
    fprintf(stderr, "usage: gainlink_mavlink --url udpin:HOST:PORT|udpout:HOST:PORT [--storage FILE] [--sysid N] [--compid N] "
                    "[--spin-us 0..1000000]\n");
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
        uint64_t next = gl_mav_node_poll(&node);
        uint64_t now = now_us(NULL);
        if (!(spin_us > 0 && now < spin_until)) {
            struct pollfd pfd = {.fd = udp.link.fd, .events = POLLIN, .revents = 0};
            int wait_ms = next > now ? (int)((next - now) / 1000u) + 1 : 0;
            int ready = poll(&pfd, 1, wait_ms);
            if (ready < 0 && errno != EINTR) {
                perror("gainlink_mavlink: poll");
                return 1;
            }
            if (ready <= 0) {
                continue;
            }
        }
        int got = drain_socket();
        if (got < 0) {
            perror("gainlink_mavlink: recv");
            return 1;
        }
        if (got && spin_us > 0) {
            spin_until = now_us(NULL) + spin_us;
        }
    }
    return 0;
}

int main(int argc, char **argv)
{
    const char *url = NULL;
    unsigned long spin_us = 0, sysid = 1, compid = 1;
    for (int i = 1; i < argc; ++i) {
        if (i + 1 < argc && strcmp(argv[i], "--url") == 0) {
            url = argv[++i];
        } else if (i + 1 < argc && strcmp(argv[i], "--storage") == 0) {
            udp.storage_path = argv[++i];
        } else if (i + 1 < argc && strcmp(argv[i], "--sysid") == 0) {
            if (parse_uint(argv[++i], 255ul, &sysid) != 0 || sysid == 0) {
                return usage();
            }
        } else if (i + 1 < argc && strcmp(argv[i], "--compid") == 0) {
            if (parse_uint(argv[++i], 255ul, &compid) != 0) {
                return usage();
            }
        } else if (i + 1 < argc && strcmp(argv[i], "--spin-us") == 0) {
            if (parse_uint(argv[++i], 1000000ul, &spin_us) != 0) {
                fprintf(stderr, "gainlink_mavlink: --spin-us must be 0..1000000\n");
                return usage();
            }
        } else {
            return usage();
        }
    }
    if (url == NULL) {
        return usage();
    }
    gl_mav_node_config_t cfg = {
        .sysid = (uint8_t)sysid,
        .compid = (uint8_t)compid,
        .chan = 0,
        .watchdog_periods = GL_WATCHDOG_PERIODS_DEFAULT,
        .port = {.ctx = &udp, .send = udp_send, .room = NULL, .now_us = now_us, .event = log_event, .link_counters = NULL},
        .storage = udp.storage_path != NULL ? gl_mav_file_init(&store_file, udp.storage_path) : NULL,
    };
    gl_status_t st = gl_mav_node_init(&node, &cfg);
    if (st != GL_OK) {
        fprintf(stderr, "gainlink_mavlink: gain set rejected (status %d)\n", (int)st);
        return 3;
    }
    char why[256] = "";
    if (gl_mav_link_open(&udp.link, url, why, sizeof why) != 0) {
        fprintf(stderr, "gainlink_mavlink: %s\n", why);
        return 2;
    }
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    printf("gainlink-mavlink %s sha256:%s %d %d %d %d %s\n", GL_NAME, GL_ARTIFACT_SHA256, GL_N, GL_M, GL_P, GL_Q, url);
    fflush(stdout);
    return serve(spin_us);
}
