/**
 * @file gl_can_socketcan.c
 * @brief SocketCAN (PF_CAN raw socket) backend of gl_can_link.h, with a kernel identifier filter.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <net/if.h>
#include <poll.h>
#include <stdio.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <linux/can.h>
#include <linux/can/raw.h>

#include "gl_can_link.h"

int gl_can_socketcan_open(gl_can_link_t *link)
{
    int s = socket(PF_CAN, SOCK_RAW, CAN_RAW);
    if (s < 0) {
        fprintf(stderr, "gainlink_can: socket(PF_CAN): %s (no CAN support in this kernel?)\n", strerror(errno));
        return -1;
    }
    struct ifreq ifr;
    memset(&ifr, 0, sizeof ifr);
    strncpy(ifr.ifr_name, link->cfg.channel, IFNAMSIZ - 1);
    if (ioctl(s, SIOCGIFINDEX, &ifr) < 0) {
        fprintf(stderr, "gainlink_can: no CAN interface %s: %s\n", link->cfg.channel, strerror(errno));
        close(s);
        return -1;
    }
    if (link->cfg.fd) {
        int on = 1;
        if (setsockopt(s, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on) < 0) {
            fprintf(stderr, "gainlink_can: %s cannot carry CAN FD: %s\n", link->cfg.channel, strerror(errno));
            close(s);
            return -1;
        }
    }
    struct can_filter filter[64];
    size_t nfilter = 0;
    for (uint32_t id = link->cfg.rx_lo; id <= link->cfg.rx_hi && nfilter < 64; ++id) {
        filter[nfilter].can_id = id;
        filter[nfilter].can_mask = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;
        ++nfilter;
    }
    if (setsockopt(s, SOL_CAN_RAW, CAN_RAW_FILTER, filter, (socklen_t)(nfilter * sizeof filter[0])) < 0) {
        fprintf(stderr, "gainlink_can: CAN_RAW_FILTER: %s\n", strerror(errno));
        close(s);
        return -1;
    }
    struct sockaddr_can addr;
    memset(&addr, 0, sizeof addr);
    addr.can_family = AF_CAN;
    addr.can_ifindex = ifr.ifr_ifindex;
    if (bind(s, (struct sockaddr *)&addr, sizeof addr) < 0) {
        fprintf(stderr, "gainlink_can: bind %s: %s\n", link->cfg.channel, strerror(errno));
        close(s);
        return -1;
    }
    link->sock = s;
    return 0;
}

int gl_can_socketcan_send(gl_can_link_t *link, const gl_can_frame_t *frame)
{
    if (frame->fd) {
        struct canfd_frame f;
        memset(&f, 0, sizeof f);
        f.can_id = frame->id & CAN_SFF_MASK;
        f.len = frame->len;
        memcpy(f.data, frame->data, frame->len);
        return write(link->sock, &f, CANFD_MTU) == (ssize_t)CANFD_MTU ? 0 : -1;
    }
    struct can_frame f;
    memset(&f, 0, sizeof f);
    f.can_id = frame->id & CAN_SFF_MASK;
    f.can_dlc = frame->len > 8 ? 8 : frame->len;
    memcpy(f.data, frame->data, f.can_dlc);
    return write(link->sock, &f, CAN_MTU) == (ssize_t)CAN_MTU ? 0 : -1;
}

int gl_can_socketcan_recv(gl_can_link_t *link, gl_can_frame_t *frame, int timeout_ms)
{
    for (;;) {
        struct pollfd pfd = {.fd = link->sock, .events = POLLIN, .revents = 0};
        int rc = poll(&pfd, 1, timeout_ms);
        if (rc == 0 || (rc < 0 && errno == EINTR)) {
            return 0;
        }
        if (rc < 0) {
            return -1;
        }
        struct canfd_frame f;
        ssize_t n = read(link->sock, &f, sizeof f);
        if (n < 0) {
            return errno == EINTR ? 0 : -1;
        }
        link->rx_read++;
        if ((f.can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG)) != 0) {
            link->rx_refused++;
            continue;
        }
        uint32_t id = f.can_id & CAN_SFF_MASK;
        if (id < link->cfg.rx_lo || id > link->cfg.rx_hi) {
            link->rx_filtered++;
            continue;
        }
        frame->id = id;
        frame->fd = n == (ssize_t)CANFD_MTU;
        frame->len = f.len > GL_CAN_MAX_DATA ? GL_CAN_MAX_DATA : f.len;
        memcpy(frame->data, f.data, frame->len);
        return 1;
    }
}
