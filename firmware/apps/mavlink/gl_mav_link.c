/**
 * @file gl_mav_link.c
 * @brief UDP link from a URL (see gl_mav_link.h).
 */
#define _GNU_SOURCE /* SO_RXQ_OVFL */
#include "gl_mav_link.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

static int resolve(const char *host, const char *port, struct sockaddr_in *out)
{
    struct addrinfo hints;
    memset(&hints, 0, sizeof hints);
    hints.ai_family = AF_INET;
    hints.ai_socktype = SOCK_DGRAM;
    struct addrinfo *res = NULL;
    if (getaddrinfo(host, port, &hints, &res) != 0 || res == NULL) {
        return -1;
    }
    memcpy(out, res->ai_addr, sizeof *out);
    freeaddrinfo(res);
    return 0;
}

int gl_mav_link_open(gl_mav_link_t *link, const char *url, char *why, size_t why_len)
{
    memset(link, 0, sizeof *link);
    link->fd = -1;
    char buf[256];
    if (snprintf(buf, sizeof buf, "%s", url) >= (int)sizeof buf) {
        snprintf(why, why_len, "URL too long");
        return -1;
    }
    char *colon = strchr(buf, ':');
    char *last = strrchr(buf, ':');
    if (colon == NULL || last == colon) {
        snprintf(why, why_len, "expected udpin:HOST:PORT or udpout:HOST:PORT, got '%s'", url);
        return -1;
    }
    *colon = '\0';
    *last = '\0';
    const char *scheme = buf;
    const char *host = colon + 1;
    const char *port = last + 1;
    if (strcmp(scheme, "udpin") == 0 || strcmp(scheme, "udp") == 0) {
        link->listen = 1;
    } else if (strcmp(scheme, "udpout") != 0) {
        snprintf(why, why_len, "unsupported link '%s' (udpin or udpout)", scheme);
        return -1;
    }
    struct sockaddr_in addr;
    if (resolve(host, port, &addr) != 0) {
        snprintf(why, why_len, "cannot resolve %s:%s", host, port);
        return -1;
    }
    link->fd = socket(AF_INET, SOCK_DGRAM, 0);
    if (link->fd < 0) {
        snprintf(why, why_len, "socket: %s", strerror(errno));
        return -1;
    }
    int big = 4 << 20; /* a burst of hostile datagrams must not push out the samples of a run */
    if (setsockopt(link->fd, SOL_SOCKET, SO_RCVBUFFORCE, &big, sizeof big) != 0) { /* beyond rmem_max: root */
        (void)setsockopt(link->fd, SOL_SOCKET, SO_RCVBUF, &big, sizeof big);
    }
    (void)setsockopt(link->fd, SOL_SOCKET, SO_SNDBUF, &big, sizeof big);
    int on = 1;
    (void)setsockopt(link->fd, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof on); /* drops counted, not guessed */
    if (link->listen) {
        int one = 1;
        (void)setsockopt(link->fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
        if (bind(link->fd, (struct sockaddr *)&addr, sizeof addr) != 0) {
            snprintf(why, why_len, "bind %s:%s: %s", host, port, strerror(errno));
            close(link->fd);
            link->fd = -1;
            return -1;
        }
    } else {
        link->peer[0] = addr;
        link->peers = 1;
    }
    (void)fcntl(link->fd, F_SETFL, fcntl(link->fd, F_GETFL, 0) | O_NONBLOCK);
    return 0;
}

static int same_addr(const struct sockaddr_in *a, const struct sockaddr_in *b)
{
    return a->sin_addr.s_addr == b->sin_addr.s_addr && a->sin_port == b->sin_port;
}

long gl_mav_link_recv(gl_mav_link_t *link, uint8_t *buf, size_t len, struct sockaddr_in *from)
{
    union {
        char space[CMSG_SPACE(sizeof(uint32_t))];
        struct cmsghdr align;
    } control;
    struct iovec iov = {.iov_base = buf, .iov_len = len};
    struct msghdr mh = {.msg_name = from, .msg_namelen = sizeof *from, .msg_iov = &iov, .msg_iovlen = 1,
                        .msg_control = control.space, .msg_controllen = sizeof control.space};
    ssize_t n = recvmsg(link->fd, &mh, 0);
    if (n < 0) {
        return (errno == EAGAIN || errno == EWOULDBLOCK || errno == ECONNREFUSED || errno == EINTR) ? 0 : -1;
    }
    link->rx_datagrams++;
    for (struct cmsghdr *c = CMSG_FIRSTHDR(&mh); c != NULL; c = CMSG_NXTHDR(&mh, c)) {
        if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_RXQ_OVFL) {
            memcpy(&link->rx_dropped, CMSG_DATA(c), sizeof link->rx_dropped);
        }
    }
    if (link->listen) {
        for (size_t k = 0; k < link->peers; ++k) {
            if (same_addr(&link->peer[k], from)) {
                return (long)n;
            }
        }
        if (link->peers < GL_MAV_MAX_PEERS) {
            link->peer[link->peers++] = *from;
        } else {
            link->peer[link->next_slot] = *from;
            link->next_slot = (link->next_slot + 1u) % GL_MAV_MAX_PEERS;
        }
    }
    return (long)n;
}

void gl_mav_link_send_to(const gl_mav_link_t *link, const uint8_t *buf, size_t len, const struct sockaddr_in *to)
{
    (void)sendto(link->fd, buf, len, 0, (const struct sockaddr *)to, sizeof *to);
}

void gl_mav_link_broadcast(const gl_mav_link_t *link, const uint8_t *buf, size_t len)
{
    for (size_t k = 0; k < link->peers; ++k) {
        gl_mav_link_send_to(link, buf, len, &link->peer[k]);
    }
}
