/**
 * @file gl_mav_link.h
 * @brief UDP endpoint of the host MAVLink app, opened from a pymavlink-style URL.
 *
 * - `udpin:HOST:PORT`  bind HOST:PORT; answer whoever sends (up to GL_MAV_MAX_PEERS peers).
 * - `udpout:HOST:PORT` send to HOST:PORT from an ephemeral port; read what comes back.
 */
#ifndef GL_MAV_LINK_H
#define GL_MAV_LINK_H

#include <netinet/in.h>
#include <stddef.h>
#include <stdint.h>

/** Peers remembered by a `udpin` link. */
#define GL_MAV_MAX_PEERS 8

/** An open UDP link. */
typedef struct gl_mav_link {
    int fd;                                      /**< Socket. */
    int listen;                                  /**< 1 for udpin. */
    struct sockaddr_in peer[GL_MAV_MAX_PEERS];   /**< Known peers (udpout: peer[0] is the target). */
    size_t peers;                                /**< Number of known peers. */
    size_t next_slot;                            /**< Peer slot to recycle next when full. */
    uint64_t rx_datagrams;                       /**< Datagrams received. */
    uint32_t rx_dropped;                         /**< Datagrams the kernel dropped on a full receive buffer
                                                      (SO_RXQ_OVFL; known at the next datagram received). */
} gl_mav_link_t;

/**
 * @brief Open a link from a URL.
 * @param[out] link  Link.
 * @param[in]  url   `udpin:HOST:PORT` or `udpout:HOST:PORT`.
 * @param[out] why   Reason of a failure.
 * @param[in]  why_len Size of `why`.
 * @return 0, or -1 (see `why`).
 */
int gl_mav_link_open(gl_mav_link_t *link, const char *url, char *why, size_t why_len);

/**
 * @brief Receive one datagram (non-blocking) and remember its sender as a peer.
 * @param[in,out] link  Link.
 * @param[out]    buf   Buffer.
 * @param[in]     len   Buffer size.
 * @param[out]    from  Sender.
 * @return Bytes received, 0 when nothing is waiting, -1 on error.
 */
long gl_mav_link_recv(gl_mav_link_t *link, uint8_t *buf, size_t len, struct sockaddr_in *from);

/**
 * @brief Send to one address.
 * @param[in] link Link.
 * @param[in] buf  Bytes.
 * @param[in] len  Length.
 * @param[in] to   Destination.
 */
void gl_mav_link_send_to(const gl_mav_link_t *link, const uint8_t *buf, size_t len, const struct sockaddr_in *to);

/**
 * @brief Send to every known peer.
 * @param[in] link Link.
 * @param[in] buf  Bytes.
 * @param[in] len  Length.
 */
void gl_mav_link_broadcast(const gl_mav_link_t *link, const uint8_t *buf, size_t len);

#endif /* GL_MAV_LINK_H */
