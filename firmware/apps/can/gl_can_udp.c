/**
 * @file gl_can_udp.c
 * @brief python-can `udp_multicast` backend of gl_can_link.h (IPv4), and the link dispatch.
 *
 * Wire format (python-can can/interfaces/udp_multicast/utils.py): one datagram per frame to
 * group:port holding a msgpack map. Sent keys: timestamp, arbitration_id, is_extended_id,
 * is_remote_frame, is_error_frame, dlc, data (bin), is_fd, bitrate_switch, error_state_indicator.
 * Received maps are read for arbitration_id, is_extended_id, is_fd, data.
 */
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <poll.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <msgpack.h>

#include "gl_can_link.h"

typedef struct {
    char buf[256];
    size_t len;
} out_buf_t;

static int out_write(void *data, const char *buf, size_t len)
{
    out_buf_t *o = data;
    if (o->len + len > sizeof o->buf) {
        return -1;
    }
    memcpy(&o->buf[o->len], buf, len);
    o->len += len;
    return 0;
}

static void pack_key(msgpack_packer *pk, const char *key)
{
    msgpack_pack_str_with_body(pk, key, strlen(key));
}

int gl_can_udp_open(gl_can_link_t *link)
{
    int s = socket(AF_INET, SOCK_DGRAM, 0);
    if (s < 0) {
        fprintf(stderr, "gainlink_can: socket(AF_INET): %s\n", strerror(errno));
        return -1;
    }
    int on = 1;
    (void)setsockopt(s, SOL_SOCKET, SO_REUSEADDR, &on, sizeof on);
    (void)setsockopt(s, SOL_SOCKET, SO_REUSEPORT, &on, sizeof on);
    int rcvbuf = 1 << 20;
    (void)setsockopt(s, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
    struct sockaddr_in addr;
    memset(&addr, 0, sizeof addr);
    addr.sin_family = AF_INET;
    addr.sin_port = htons(link->cfg.port);
    addr.sin_addr.s_addr = htonl(INADDR_ANY);
    struct ip_mreq mreq;
    memset(&mreq, 0, sizeof mreq);
    if (inet_pton(AF_INET, link->cfg.channel, &mreq.imr_multiaddr) != 1) {
        fprintf(stderr, "gainlink_can: %s is not an IPv4 multicast group\n", link->cfg.channel);
        close(s);
        return -1;
    }
    mreq.imr_interface.s_addr = htonl(INADDR_ANY);
    unsigned char ttl = (unsigned char)link->cfg.hop_limit;
    unsigned char loop = 1;
    if (bind(s, (struct sockaddr *)&addr, sizeof addr) < 0 ||
        setsockopt(s, IPPROTO_IP, IP_ADD_MEMBERSHIP, &mreq, sizeof mreq) < 0 ||
        setsockopt(s, IPPROTO_IP, IP_MULTICAST_TTL, &ttl, sizeof ttl) < 0 ||
        setsockopt(s, IPPROTO_IP, IP_MULTICAST_LOOP, &loop, sizeof loop) < 0) {
        fprintf(stderr, "gainlink_can: cannot join %s:%u: %s\n", link->cfg.channel, (unsigned)link->cfg.port,
                strerror(errno));
        close(s);
        return -1;
    }
    link->sock = s;
    return 0;
}

int gl_can_udp_send(gl_can_link_t *link, const gl_can_frame_t *frame)
{
    out_buf_t out = {.len = 0};
    msgpack_packer pk;
    msgpack_packer_init(&pk, &out, out_write);
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    msgpack_pack_map(&pk, 10);
    pack_key(&pk, "timestamp");
    msgpack_pack_double(&pk, (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec);
    pack_key(&pk, "arbitration_id");
    msgpack_pack_uint32(&pk, frame->id);
    pack_key(&pk, "is_extended_id");
    msgpack_pack_false(&pk);
    pack_key(&pk, "is_remote_frame");
    msgpack_pack_false(&pk);
    pack_key(&pk, "is_error_frame");
    msgpack_pack_false(&pk);
    pack_key(&pk, "dlc");
    msgpack_pack_uint32(&pk, frame->len);
    pack_key(&pk, "data");
    msgpack_pack_bin(&pk, frame->len);
    msgpack_pack_bin_body(&pk, frame->data, frame->len);
    pack_key(&pk, "is_fd");
    if (frame->fd) {
        msgpack_pack_true(&pk);
    } else {
        msgpack_pack_false(&pk);
    }
    pack_key(&pk, "bitrate_switch");
    msgpack_pack_false(&pk);
    pack_key(&pk, "error_state_indicator");
    msgpack_pack_false(&pk);
    if (out.len == 0 || out.len >= sizeof out.buf) {
        return -1;
    }
    struct sockaddr_in dest;
    memset(&dest, 0, sizeof dest);
    dest.sin_family = AF_INET;
    dest.sin_port = htons(link->cfg.port);
    if (inet_pton(AF_INET, link->cfg.channel, &dest.sin_addr) != 1) {
        return -1;
    }
    return sendto(link->sock, out.buf, out.len, 0, (struct sockaddr *)&dest, sizeof dest) == (ssize_t)out.len ? 0 : -1;
}

static int key_is(const msgpack_object *k, const char *name)
{
    size_t n = strlen(name);
    return k->type == MSGPACK_OBJECT_STR && k->via.str.size == n && memcmp(k->via.str.ptr, name, n) == 0;
}

/* Decode one datagram; 1 when it is a standard data frame, 0 to skip it. */
static int decode(const char *buf, size_t len, gl_can_frame_t *frame, msgpack_unpacked *msg)
{
    size_t off = 0;
    if (msgpack_unpack_next(msg, buf, len, &off) != MSGPACK_UNPACK_SUCCESS || msg->data.type != MSGPACK_OBJECT_MAP) {
        return 0;
    }
    int have_id = 0, have_data = 0;
    memset(frame, 0, sizeof *frame);
    const msgpack_object_map *map = &msg->data.via.map;
    for (uint32_t i = 0; i < map->size; ++i) {
        const msgpack_object *k = &map->ptr[i].key;
        const msgpack_object *v = &map->ptr[i].val;
        if (key_is(k, "arbitration_id") && v->type == MSGPACK_OBJECT_POSITIVE_INTEGER) {
            frame->id = (uint32_t)v->via.u64;
            have_id = 1;
        } else if (key_is(k, "is_extended_id") && v->type == MSGPACK_OBJECT_BOOLEAN && v->via.boolean) {
            return 0;
        } else if ((key_is(k, "is_remote_frame") || key_is(k, "is_error_frame")) && v->type == MSGPACK_OBJECT_BOOLEAN &&
                   v->via.boolean) {
            return 0;
        } else if (key_is(k, "is_fd") && v->type == MSGPACK_OBJECT_BOOLEAN) {
            frame->fd = v->via.boolean ? 1 : 0;
        } else if (key_is(k, "data") && (v->type == MSGPACK_OBJECT_BIN || v->type == MSGPACK_OBJECT_STR)) {
            size_t n = v->type == MSGPACK_OBJECT_BIN ? v->via.bin.size : v->via.str.size;
            const char *p = v->type == MSGPACK_OBJECT_BIN ? v->via.bin.ptr : v->via.str.ptr;
            if (n > GL_CAN_MAX_DATA) {
                return 0;
            }
            memcpy(frame->data, p, n);
            frame->len = (uint8_t)n;
            have_data = 1;
        }
    }
    return have_id && have_data;
}

int gl_can_udp_recv(gl_can_link_t *link, gl_can_frame_t *frame, int timeout_ms)
{
    static msgpack_unpacked msg;
    static int msg_ready;
    if (!msg_ready) {
        msgpack_unpacked_init(&msg);
        msg_ready = 1;
    }
    char buf[512];
    for (;;) {
        struct pollfd pfd = {.fd = link->sock, .events = POLLIN, .revents = 0};
        int rc = poll(&pfd, 1, timeout_ms);
        if (rc == 0 || (rc < 0 && errno == EINTR)) {
            return 0;
        }
        if (rc < 0) {
            return -1;
        }
        ssize_t n = recv(link->sock, buf, sizeof buf, 0);
        if (n < 0) {
            return errno == EINTR ? 0 : -1;
        }
        if (!decode(buf, (size_t)n, frame, &msg) || frame->id < link->cfg.rx_lo || frame->id > link->cfg.rx_hi) {
            link->rx_foreign++;
            continue;
        }
        return 1;
    }
}

int gl_can_link_open(gl_can_link_t *link, const gl_can_config_t *cfg)
{
    memset(link, 0, sizeof *link);
    link->cfg = *cfg;
    link->sock = -1;
    return cfg->backend == GL_CAN_SOCKETCAN ? gl_can_socketcan_open(link) : gl_can_udp_open(link);
}

int gl_can_link_send(gl_can_link_t *link, const gl_can_frame_t *frame)
{
    return link->cfg.backend == GL_CAN_SOCKETCAN ? gl_can_socketcan_send(link, frame) : gl_can_udp_send(link, frame);
}

int gl_can_link_recv(gl_can_link_t *link, gl_can_frame_t *frame, int timeout_ms)
{
    return link->cfg.backend == GL_CAN_SOCKETCAN ? gl_can_socketcan_recv(link, frame, timeout_ms)
                                                 : gl_can_udp_recv(link, frame, timeout_ms);
}

void gl_can_link_close(gl_can_link_t *link)
{
    if (link->sock >= 0) {
        close(link->sock);
        link->sock = -1;
    }
}
