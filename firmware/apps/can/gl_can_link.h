/**
 * @file gl_can_link.h
 * @brief One small interface over two CAN links: SocketCAN raw sockets and python-can's udp_multicast.
 *
 * udp_multicast carries one frame per UDP datagram as a msgpack map {arbitration_id, is_extended_id,
 * dlc, data, is_fd, ...} sent to group:port; every member receives its own datagrams, so receivers
 * filter by identifier (gl_can_link_t::rx_lo .. rx_hi). SocketCAN gets a kernel filter for the same range.
 */
#ifndef GAINLINK_GL_CAN_LINK_H
#define GAINLINK_GL_CAN_LINK_H

#include <stdint.h>

/** Largest payload (CAN FD). */
#define GL_CAN_MAX_DATA 64

/** One CAN frame (11-bit identifiers only). */
typedef struct gl_can_frame {
    uint32_t id;                    /**< Arbitration identifier. */
    uint8_t len;                    /**< Payload bytes (0..8 classic, 0..64 FD). */
    uint8_t fd;                     /**< 1 for a CAN FD frame. */
    uint8_t data[GL_CAN_MAX_DATA];  /**< Payload. */
} gl_can_frame_t;

/** Which link. */
typedef enum gl_can_backend { GL_CAN_SOCKETCAN = 0, GL_CAN_UDP = 1 } gl_can_backend_t;

/** Link configuration (from the command line). */
typedef struct gl_can_config {
    gl_can_backend_t backend;  /**< Link kind. */
    const char *channel;       /**< SocketCAN interface name, or the IPv4 multicast group. */
    uint16_t port;             /**< UDP port (udp_multicast): where the node listens. */
    uint16_t reply_port;       /**< UDP port it sends to (udp_multicast; 0: `port`, where it hears its own frames). */
    int hop_limit;             /**< IPv4 multicast TTL (udp_multicast); 0 keeps frames on the host. */
    int fd;                    /**< 1 to send/accept CAN FD frames. */
    uint32_t rx_lo;            /**< Lowest identifier to receive. */
    uint32_t rx_hi;            /**< Highest identifier to receive. */
} gl_can_config_t;

/**
 * @brief An open link and what it received.
 *
 * Every datagram/frame that reached the socket is in exactly one of: returned by gl_can_link_recv(),
 * `rx_filtered`, `rx_refused`; `rx_dropped` counts those the kernel dropped before the app read them.
 */
typedef struct gl_can_link {
    gl_can_config_t cfg;       /**< Its configuration. */
    int sock;                  /**< Socket descriptor. */
    uint32_t group;            /**< udp_multicast: the group's IPv4 address (network order), parsed once. */
    uint64_t rx_read;          /**< Datagrams / frames read from the socket. */
    uint64_t rx_filtered;      /**< Well-formed frames with identifiers outside [rx_lo, rx_hi] (our own echo too). */
    uint64_t rx_refused;       /**< Not a standard data frame: malformed or oversized datagram, extended, remote,
                                    error frame, or a payload too long for its kind. */
    uint64_t rx_dropped;       /**< Dropped by the kernel on a full receive buffer (udp_multicast: SO_RXQ_OVFL). */
} gl_can_link_t;

/**
 * @brief Open a link.
 * @param[out] link  Link to fill.
 * @param[in]  cfg   Configuration.
 * @return 0, or -1 with errno set (a message is written to stderr).
 */
int gl_can_link_open(gl_can_link_t *link, const gl_can_config_t *cfg);

/**
 * @brief Send one frame.
 * @param[in,out] link   Open link.
 * @param[in]     frame  Frame.
 * @return 0 or -1.
 */
int gl_can_link_send(gl_can_link_t *link, const gl_can_frame_t *frame);

/**
 * @brief Receive the next frame whose identifier is in [rx_lo, rx_hi].
 * @param[in,out] link        Open link.
 * @param[out]    frame       Received frame.
 * @param[in]     timeout_ms  Wait at most this long (-1: forever).
 * @return 1 frame received, 0 timeout or interrupted, -1 error.
 */
int gl_can_link_recv(gl_can_link_t *link, gl_can_frame_t *frame, int timeout_ms);

/** @brief Close a link. @param[in,out] link Link. */
void gl_can_link_close(gl_can_link_t *link);

/* Backend entry points (used by gl_can_link_* dispatch in gl_can_udp.c). */
int gl_can_socketcan_open(gl_can_link_t *link);
int gl_can_socketcan_send(gl_can_link_t *link, const gl_can_frame_t *frame);
int gl_can_socketcan_recv(gl_can_link_t *link, gl_can_frame_t *frame, int timeout_ms);
int gl_can_udp_open(gl_can_link_t *link);
int gl_can_udp_send(gl_can_link_t *link, const gl_can_frame_t *frame);
int gl_can_udp_recv(gl_can_link_t *link, gl_can_frame_t *frame, int timeout_ms);

#endif /* GAINLINK_GL_CAN_LINK_H */
