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

#include "gl_can_udp.h"

typedef struct {
    char *buf;
    size_t cap;
    size_t len;
    int overflow;
} out_buf_t;

static int out_write(void *data, const char *buf, size_t len)
{
    out_buf_t *o = data;
    if (o->len + len > o->cap) {
        o->overflow = 1;
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
    int rcvbuf = 4 << 20; /* a burst of hostile datagrams must not push out the samples of a run */
    if (setsockopt(s, SOL_SOCKET, SO_RCVBUFFORCE, &rcvbuf, sizeof rcvbuf) != 0) { /* beyond rmem_max: root */
        (void)setsockopt(s, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
    }
    (void)setsockopt(s, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof on); /* drops counted, not guessed */
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
    link->group = mreq.imr_multiaddr.s_addr;
    link->sock = s;
    return 0;
}

size_t gl_can_udp_encode(const gl_can_frame_t *frame, double timestamp, char *buf, size_t cap)
{
    out_buf_t out = {.buf = buf, .cap = cap, .len = 0};
    msgpack_packer pk;
    msgpack_packer_init(&pk, &out, out_write);
    msgpack_pack_map(&pk, 10);
    pack_key(&pk, "timestamp");
    msgpack_pack_double(&pk, timestamp);
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
    return out.overflow ? 0u : out.len;
}

int gl_can_udp_send(gl_can_link_t *link, const gl_can_frame_t *frame)
{
    char buf[GL_CAN_UDP_MAX_DATAGRAM];
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    size_t len = gl_can_udp_encode(frame, (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec, buf, sizeof buf);
    if (len == 0u) {
        return -1;
    }
    struct sockaddr_in dest;
    memset(&dest, 0, sizeof dest);
    dest.sin_family = AF_INET;
    dest.sin_port = htons(link->cfg.reply_port != 0u ? link->cfg.reply_port : link->cfg.port);
    dest.sin_addr.s_addr = link->group;
    return sendto(link->sock, buf, len, 0, (struct sockaddr *)&dest, sizeof dest) == (ssize_t)len ? 0 : -1;
}

static int key_is(const msgpack_object *k, const char *name)
{
    size_t n = strlen(name);
    return k->type == MSGPACK_OBJECT_STR && k->via.str.size == n && memcmp(k->via.str.ptr, name, n) == 0;
}

/** Largest standard (11-bit) identifier. */
#define GL_CAN_STD_ID_MAX 0x7FFu

/**
 * Bytes that follow a msgpack scalar's type byte `t` before the next item (its length field and body),
 * or -1 for a container (array, map) or a reserved byte. `p` points at the type byte, `left` bytes remain.
 */
static long scalar_size(const uint8_t *p, size_t left)
{
    const uint8_t t = p[0];
    if (t <= 0x7Fu || t >= 0xE0u || (t >= 0xC2u && t <= 0xC3u) || t == 0xC0u) {
        return 0; /* fixint, nil, bool */
    }
    if (t >= 0xA0u && t <= 0xBFu) {
        return t & 0x1Fu; /* fixstr */
    }
    static const uint8_t fixed[] = {
        [0xCA - 0xC4] = 4, [0xCB - 0xC4] = 8, [0xCC - 0xC4] = 1, [0xCD - 0xC4] = 2, [0xCE - 0xC4] = 4,
        [0xCF - 0xC4] = 8, [0xD0 - 0xC4] = 1, [0xD1 - 0xC4] = 2, [0xD2 - 0xC4] = 4, [0xD3 - 0xC4] = 8,
        [0xD4 - 0xC4] = 2, [0xD5 - 0xC4] = 3, [0xD6 - 0xC4] = 5, [0xD7 - 0xC4] = 9, [0xD8 - 0xC4] = 17,
    };
    if (t >= 0xCAu && t <= 0xD8u) {
        return fixed[t - 0xC4u]; /* float, (u)int, fixext */
    }
    size_t width;
    switch (t) {
    case 0xC4: case 0xC7: case 0xD9: width = 1; break; /* bin8, ext8, str8 */
    case 0xC5: case 0xC8: case 0xDA: width = 2; break;
    case 0xC6: case 0xC9: case 0xDB: width = 4; break;
    default: return -1; /* arrays, maps, 0xC1 */
    }
    if (left < 1u + width) {
        return -1;
    }
    size_t n = 0;
    for (size_t i = 0; i < width; ++i) {
        n = (n << 8) | p[1 + i];
    }
    const size_t ext = (t >= 0xC7u && t <= 0xC9u) ? 1u : 0u; /* ext carries a type byte */
    return n > left ? -1 : (long)(width + ext + n);
}

/**
 * Shape of a python-can frame: one fixmap (at most 15 entries) of scalars, strings and binaries, within `len`.
 * Checked before msgpack_unpack_next(), which would otherwise allocate for whatever element count a
 * hostile container declares (a 5-byte map32 header asks for 256 GiB).
 */
static int flat_map(const uint8_t *p, size_t len)
{
    if (len < 1u || (p[0] & 0xF0u) != 0x80u) {
        return 0;
    }
    size_t at = 1;
    for (unsigned item = 0; item < 2u * (p[0] & 0x0Fu); ++item) {
        if (at >= len) {
            return 0;
        }
        long body = scalar_size(&p[at], len - at);
        if (body < 0 || (size_t)body > len - at - 1u) {
            return 0;
        }
        at += 1u + (size_t)body;
    }
    return 1;
}

int gl_can_udp_decode(const char *buf, size_t len, gl_can_frame_t *frame, msgpack_unpacked *msg)
{
    size_t off = 0;
    if (!flat_map((const uint8_t *)buf, len)) {
        return 0;
    }
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
            if (v->via.u64 > GL_CAN_STD_ID_MAX) {
                return 0; /* an extended or out-of-range id must not alias a standard one */
            }
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
    if (!frame->fd && frame->len > 8u) {
        return 0; /* a classic frame carries at most 8 bytes */
    }
    return have_id && have_data;
}

/* Kernel drop count from the SO_RXQ_OVFL control message (cumulative for the socket). */
static void note_drops(gl_can_link_t *link, struct msghdr *mh)
{
    for (struct cmsghdr *c = CMSG_FIRSTHDR(mh); c != NULL; c = CMSG_NXTHDR(mh, c)) {
        if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_RXQ_OVFL) {
            uint32_t dropped;
            memcpy(&dropped, CMSG_DATA(c), sizeof dropped);
            link->rx_dropped = dropped;
        }
    }
}

int gl_can_udp_recv(gl_can_link_t *link, gl_can_frame_t *frame, int timeout_ms)
{
    static msgpack_unpacked msg;
    static int msg_ready;
    if (!msg_ready) {
        msgpack_unpacked_init(&msg);
        msg_ready = 1;
    }
    char buf[GL_CAN_UDP_MAX_DATAGRAM];
    union {
        char space[CMSG_SPACE(sizeof(uint32_t))];
        struct cmsghdr align;
    } control;
    for (;;) {
        struct pollfd pfd = {.fd = link->sock, .events = POLLIN, .revents = 0};
        int rc = poll(&pfd, 1, timeout_ms);
        if (rc == 0 || (rc < 0 && errno == EINTR)) {
            return 0;
        }
        if (rc < 0) {
            return -1;
        }
        struct iovec iov = {.iov_base = buf, .iov_len = sizeof buf};
        struct msghdr mh = {.msg_iov = &iov, .msg_iovlen = 1, .msg_control = control.space,
                            .msg_controllen = sizeof control.space};
        ssize_t n = recvmsg(link->sock, &mh, MSG_TRUNC | MSG_DONTWAIT);
        if (n < 0) {
            return (errno == EINTR || errno == EAGAIN || errno == EWOULDBLOCK) ? 0 : -1;
        }
        link->rx_read++;
        note_drops(link, &mh);
        if ((size_t)n > sizeof buf || !gl_can_udp_decode(buf, (size_t)n, frame, &msg)) {
            link->rx_refused++; /* longer than any frame python-can sends, or not a standard data frame */
            continue;
        }
        if (frame->id < link->cfg.rx_lo || frame->id > link->cfg.rx_hi) {
            link->rx_filtered++;
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
