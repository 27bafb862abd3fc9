/**
 * @file main.c
 * @brief Host executable `gainlink_mavlink`: the control loop behind a MAVLink 2 link over UDP.
 *
 * Usage: `gainlink_mavlink --url udpin:127.0.0.1:14550 [--storage FILE] [--sysid 1] [--compid 1] [--spin-us N]`
 *
 * - `--spin-us N` (default 0) reads without blocking for N us after each received datagram before
 *   blocking in poll() again: lower lockstep latency for 100 % of a core while spinning.
 * - HEARTBEAT once a second (MAV_TYPE_GENERIC, MAV_AUTOPILOT_GENERIC) to every known peer.
 * - AUTOPILOT_VERSION on MAV_CMD_REQUEST_MESSAGE(148) or MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
 *   capabilities MAVLINK2 | PARAM_ENCODE_BYTEWISE.
 * - Parameter protocol over the gain set (naming scheme in gl_mav_params.h): PARAM_REQUEST_LIST,
 *   PARAM_REQUEST_READ by id or index (PARAM_ERROR when unknown), PARAM_SET always answered with
 *   PARAM_VALUE (the value now held: unchanged when refused, then followed by PARAM_ERROR).
 * - MAV_CMD_PREFLIGHT_STORAGE param1 = 0 reload from --storage, 1 write the committed set to it,
 *   2 reset to the compiled gain set; COMMAND_ACK for each. The file is loaded at start when present.
 * - HIL samples: DEBUG_FLOAT_ARRAY array_id 1 (`GL_SAMPLE`): data = y[0..p-1] then r[0..q-1];
 *   answered by HIL_ACTUATOR_CONTROLS with the same time_usec, controls[0..m-1] = u and flags
 *   bit 0 fault (sample refused), bit 1 watchdog, bit 2 reset done, bits 8.. saturation per input.
 *   array_id 2 (`GL_RESET`) resets the loop state; array_id 3 (`GL_IDLE`) is a period without a
 *   measurement (watchdog). A committed gain set is staged into the loop right before the next step.
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

#include "common/mavlink.h"
#include "gainlink/gl_loop.h"
#include "gl_mav_link.h"
#include "gl_mav_params.h"
#include "gl_mav_store.h"

#define HIL_ARRAY_SAMPLE 1
#define HIL_ARRAY_RESET 2
#define HIL_ARRAY_IDLE 3
#define HIL_FLAG_FAULT 0x1u
#define HIL_FLAG_WATCHDOG 0x2u
#define HIL_FLAG_RESET 0x4u
#define HIL_SAT_SHIFT 8

_Static_assert(GL_P + GL_Q <= 58, "DEBUG_FLOAT_ARRAY carries at most 58 values (y and r)");
_Static_assert(GL_M <= 16, "HIL_ACTUATOR_CONTROLS carries at most 16 commands");

static gl_loop_t loop;
static gl_mav_params_t table;
static gl_mav_link_t link;
static int dirty; /* committed set not yet staged into the loop */
static uint8_t sysid = 1;
static uint8_t compid = MAV_COMP_ID_AUTOPILOT1;
static const char *storage;
static volatile sig_atomic_t stop;

static void on_signal(int sig)
{
    (void)sig;
    stop = 1;
}

static void send_msg(const mavlink_message_t *msg, const struct sockaddr_in *to)
{
    uint8_t buf[MAVLINK_MAX_PACKET_LEN];
    uint16_t len = mavlink_msg_to_send_buffer(buf, msg);
    if (to != NULL) {
        gl_mav_link_send_to(&link, buf, len, to);
    } else {
        gl_mav_link_broadcast(&link, buf, len);
    }
}

static void send_heartbeat(void)
{
    mavlink_message_t msg;
    mavlink_msg_heartbeat_pack(sysid, compid, &msg, MAV_TYPE_GENERIC, MAV_AUTOPILOT_GENERIC, 0, 0, MAV_STATE_ACTIVE);
    send_msg(&msg, NULL);
}

static void send_param(uint16_t index, const struct sockaddr_in *to)
{
    mavlink_message_t msg;
    mavlink_msg_param_value_pack(sysid, compid, &msg, table.param[index].id, gl_mav_params_value(&table, index),
                                 table.param[index].type, table.count, index);
    send_msg(&msg, to);
}

static void send_param_error(const mavlink_message_t *req, const char *id, int16_t index, uint8_t error,
                             const struct sockaddr_in *to)
{
    char pid[GL_MAV_ID_LEN + 1];
    memcpy(pid, id, GL_MAV_ID_LEN);
    pid[GL_MAV_ID_LEN] = '\0';
    mavlink_message_t msg;
    mavlink_msg_param_error_pack(sysid, compid, &msg, req->sysid, req->compid, pid, index, error);
    send_msg(&msg, to);
}

static void send_ack(const mavlink_message_t *req, uint16_t command, uint8_t result, const struct sockaddr_in *to)
{
    mavlink_message_t msg;
    mavlink_msg_command_ack_pack(sysid, compid, &msg, command, result, 0, 0, req->sysid, req->compid);
    send_msg(&msg, to);
}

static void send_version(const struct sockaddr_in *to)
{
    uint8_t custom[8];
    memcpy(custom, GL_ARTIFACT_SHA256, sizeof custom);
    const uint8_t none[8] = {0};
    const uint8_t uid2[18] = {0};
    mavlink_message_t msg;
    mavlink_msg_autopilot_version_pack(sysid, compid, &msg,
                                       MAV_PROTOCOL_CAPABILITY_MAVLINK2 | MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE,
                                       0x00010000u, 0, 0, 0, custom, none, none, 0, 0, table.committed.crc32, uid2);
    send_msg(&msg, to);
}

static int for_us(uint8_t target_system, uint8_t target_component)
{
    return (target_system == 0 || target_system == sysid) && (target_component == 0 || target_component == compid);
}

static void handle_param_set(const mavlink_message_t *msg, const struct sockaddr_in *from)
{
    mavlink_param_set_t set;
    mavlink_msg_param_set_decode(msg, &set);
    if (!for_us(set.target_system, set.target_component)) {
        return;
    }
    int32_t k = gl_mav_params_find(&table, set.param_id);
    if (k < 0) {
        send_param_error(msg, set.param_id, -1, MAV_PARAM_ERROR_DOES_NOT_EXIST, from);
        return;
    }
    gl_mav_set_result_t r = gl_mav_params_set(&table, (uint16_t)k, set.param_value, set.param_type);
    if (r == GL_MAV_SET_OK && table.param[k].header >= 0) {
        dirty = 1;
        fprintf(stderr, "gainlink_mavlink: committed gain set crc32 0x%08lx\n", (unsigned long)table.committed.crc32);
    }
    send_param((uint16_t)k, NULL);
    if (r != GL_MAV_SET_OK) {
        uint8_t err = r == GL_MAV_SET_READ_ONLY ? MAV_PARAM_ERROR_READ_ONLY : MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE;
        if (table.param[k].header >= 0 && r == GL_MAV_SET_BAD_VALUE) {
            fprintf(stderr, "gainlink_mavlink: commit refused (status %ld)\n", (long)table.last_refusal);
        }
        send_param_error(msg, set.param_id, (int16_t)k, err, from);
    }
}

static void handle_param_read(const mavlink_message_t *msg, const struct sockaddr_in *from)
{
    mavlink_param_request_read_t rd;
    mavlink_msg_param_request_read_decode(msg, &rd);
    if (!for_us(rd.target_system, rd.target_component)) {
        return;
    }
    int32_t k = rd.param_index >= 0 ? rd.param_index : gl_mav_params_find(&table, rd.param_id);
    if (k < 0 || k >= (int32_t)table.count) {
        send_param_error(msg, rd.param_id, rd.param_index, MAV_PARAM_ERROR_DOES_NOT_EXIST, from);
        return;
    }
    send_param((uint16_t)k, from);
}

static uint8_t storage_command(float action)
{
    char why[256] = "";
    if (action == 1.0f) {
        if (storage == NULL || gl_mav_store_save(&table, storage) != 0) {
            fprintf(stderr, "gainlink_mavlink: cannot write parameters to %s\n", storage ? storage : "(no --storage)");
            return MAV_RESULT_FAILED;
        }
        fprintf(stderr, "gainlink_mavlink: parameters written to %s\n", storage);
        return MAV_RESULT_ACCEPTED;
    }
    if (action == 0.0f) {
        if (storage == NULL || gl_mav_store_load(&table, storage, why, sizeof why) != 0) {
            fprintf(stderr, "gainlink_mavlink: cannot reload parameters: %s\n", why);
            return MAV_RESULT_FAILED;
        }
        dirty = 1;
        return MAV_RESULT_ACCEPTED;
    }
    if (action == 2.0f) {
        if (gl_mav_params_replace(&table, &gl_gains_default) != GL_OK) {
            return MAV_RESULT_FAILED;
        }
        dirty = 1;
        return MAV_RESULT_ACCEPTED;
    }
    return MAV_RESULT_UNSUPPORTED;
}

static void handle_command(const mavlink_message_t *msg, const struct sockaddr_in *from)
{
    mavlink_command_long_t cmd;
    mavlink_msg_command_long_decode(msg, &cmd);
    if (!for_us(cmd.target_system, cmd.target_component)) {
        return;
    }
    switch (cmd.command) {
    case MAV_CMD_REQUEST_MESSAGE:
        if (cmd.param1 == (float)MAVLINK_MSG_ID_AUTOPILOT_VERSION) {
            send_ack(msg, cmd.command, MAV_RESULT_ACCEPTED, from);
            send_version(from);
        } else if (cmd.param1 == (float)MAVLINK_MSG_ID_HEARTBEAT) {
            send_ack(msg, cmd.command, MAV_RESULT_ACCEPTED, from);
            send_heartbeat();
        } else {
            send_ack(msg, cmd.command, MAV_RESULT_UNSUPPORTED, from);
        }
        break;
    case MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
        send_ack(msg, cmd.command, MAV_RESULT_ACCEPTED, from);
        send_version(from);
        break;
    case MAV_CMD_PREFLIGHT_STORAGE:
        send_ack(msg, cmd.command, storage_command(cmd.param1), from);
        break;
    default:
        send_ack(msg, cmd.command, MAV_RESULT_UNSUPPORTED, from);
        break;
    }
}

static void stage_if_dirty(void)
{
    if (dirty) {
        gl_status_t st = gl_loop_stage(&loop, &table.committed);
        if (st != GL_OK) {
            fprintf(stderr, "gainlink_mavlink: staging the committed set failed (status %d)\n", (int)st);
        }
        dirty = 0;
    }
}

static void handle_sample(const mavlink_message_t *msg, const struct sockaddr_in *from)
{
    mavlink_debug_float_array_t in;
    mavlink_msg_debug_float_array_decode(msg, &in);
    float u[GL_M];
    uint64_t flags = 0;
    gl_status_t st = GL_OK;
    if (in.array_id == HIL_ARRAY_SAMPLE) {
        stage_if_dirty();
        st = gl_loop_step(&loop, &in.data[0], GL_Q > 0 ? &in.data[GL_P] : NULL, u);
        if (st < 0) {
            flags |= HIL_FLAG_FAULT;
        }
        flags |= (uint64_t)loop.sat_mask << HIL_SAT_SHIFT;
    } else if (in.array_id == HIL_ARRAY_RESET) {
        stage_if_dirty();
        (void)gl_loop_reset(&loop);
        memset(u, 0, sizeof u);
        flags |= HIL_FLAG_RESET;
    } else if (in.array_id == HIL_ARRAY_IDLE) {
        st = gl_loop_idle(&loop, u);
        if (st == GL_ERR_WATCHDOG) {
            flags |= HIL_FLAG_WATCHDOG;
        }
    } else {
        return;
    }
    float controls[16] = {0};
    memcpy(controls, u, sizeof u);
    mavlink_message_t out;
    mavlink_msg_hil_actuator_controls_pack(sysid, compid, &out, in.time_usec, controls, 0, flags);
    send_msg(&out, from);
}

static void dispatch(const mavlink_message_t *msg, const struct sockaddr_in *from)
{
    switch (msg->msgid) {
    case MAVLINK_MSG_ID_DEBUG_FLOAT_ARRAY: handle_sample(msg, from); break;
    case MAVLINK_MSG_ID_PARAM_SET: handle_param_set(msg, from); break;
    case MAVLINK_MSG_ID_PARAM_REQUEST_READ: handle_param_read(msg, from); break;
    case MAVLINK_MSG_ID_PARAM_REQUEST_LIST: {
        mavlink_param_request_list_t rq;
        mavlink_msg_param_request_list_decode(msg, &rq);
        if (for_us(rq.target_system, rq.target_component)) {
            for (uint16_t k = 0; k < table.count; ++k) {
                send_param(k, from);
            }
        }
        break;
    }
    case MAVLINK_MSG_ID_COMMAND_LONG: handle_command(msg, from); break;
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

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int usage(void)
{
    fprintf(stderr, "usage: gainlink_mavlink --url udpin:HOST:PORT|udpout:HOST:PORT [--storage FILE] [--sysid N] [--compid N] "
                    "[--spin-us 0..1000000]\n");
    return 2;
}

int main(int argc, char **argv)
{
    const char *url = NULL;
    unsigned long spin_us = 0;
    for (int i = 1; i < argc; ++i) {
        if (i + 1 < argc && strcmp(argv[i], "--url") == 0) {
            url = argv[++i];
        } else if (i + 1 < argc && strcmp(argv[i], "--storage") == 0) {
            storage = argv[++i];
        } else if (i + 1 < argc && strcmp(argv[i], "--sysid") == 0) {
            sysid = (uint8_t)strtoul(argv[++i], NULL, 10);
        } else if (i + 1 < argc && strcmp(argv[i], "--compid") == 0) {
            compid = (uint8_t)strtoul(argv[++i], NULL, 10);
        } else if (i + 1 < argc && strcmp(argv[i], "--spin-us") == 0) {
            if (parse_uint(argv[++i], 1000000ul, &spin_us) != 0) {
                fprintf(stderr, "gainlink_mavlink: --spin-us must be 0..1000000\n");
                return usage();
            }
        } else {
            return usage();
        }
    }
    if (url == NULL || sysid == 0) {
        return usage();
    }
    gl_mav_params_init(&table, &gl_gains_default);
    if (storage != NULL) {
        char why[256] = "";
        int rc = gl_mav_store_load(&table, storage, why, sizeof why);
        if (rc == 0) {
            fprintf(stderr, "gainlink_mavlink: loaded parameters from %s (crc32 0x%08lx)\n", storage,
                    (unsigned long)table.committed.crc32);
        } else if (rc < 0) {
            fprintf(stderr, "gainlink_mavlink: ignoring %s: %s; using the compiled gain set\n", storage, why);
        }
    }
    gl_status_t st = gl_loop_init(&loop, &table.committed, GL_WATCHDOG_PERIODS_DEFAULT);
    if (st != GL_OK) {
        fprintf(stderr, "gainlink_mavlink: gain set rejected (status %d)\n", (int)st);
        return 3;
    }
    char why[256] = "";
    if (gl_mav_link_open(&link, url, why, sizeof why) != 0) {
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

    uint8_t buf[65536];
    struct sockaddr_in from;
    mavlink_message_t msg;
    mavlink_status_t status;
    double next_beat = now_s();
    double spin_until = 0.0; /* read without blocking until then (--spin-us after each datagram) */
    while (!stop) {
        double now = now_s();
        if (now >= next_beat) {
            send_heartbeat();
            next_beat = now + 1.0;
        }
        if (!(spin_us > 0 && now < spin_until)) {
            struct pollfd pfd = {.fd = link.fd, .events = POLLIN, .revents = 0};
            int wait_ms = (int)((next_beat - now) * 1000.0) + 1;
            int ready = poll(&pfd, 1, wait_ms);
            if (ready < 0 && errno != EINTR) {
                perror("gainlink_mavlink: poll");
                return 1;
            }
            if (ready <= 0) {
                continue;
            }
        }
        long n;
        int got = 0;
        size_t peers_before = link.peers;
        while ((n = gl_mav_link_recv(&link, buf, sizeof buf, &from)) > 0) {
            got = 1;
            for (long i = 0; i < n; ++i) {
                if (mavlink_parse_char(MAVLINK_COMM_0, buf[i], &msg, &status)) {
                    dispatch(&msg, &from);
                }
            }
        }
        if (got && spin_us > 0) {
            spin_until = now_s() + 1e-6 * (double)spin_us;
        }
        if (link.peers != peers_before) {
            send_heartbeat(); /* a new peer hears us at once, not up to a second later */
        }
    }
    return 0;
}
