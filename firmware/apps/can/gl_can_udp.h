/**
 * @file gl_can_udp.h
 * @brief The udp_multicast datagram decoder of gl_can_udp.c, on its own for the fuzz harness and tests.
 */
#ifndef GAINLINK_GL_CAN_UDP_H
#define GAINLINK_GL_CAN_UDP_H

#include <stddef.h>

#include <msgpack.h>

#include "gl_can_link.h"

/**
 * @brief Decode one udp_multicast datagram (a msgpack map) into a frame.
 *
 * Accepts only a standard (11-bit id, not extended, not remote, not error) data frame whose payload
 * fits: at most 8 bytes unless `is_fd` is true, at most GL_CAN_MAX_DATA bytes for FD. Anything else,
 * including a truncated or malformed map, is refused; nothing is read beyond `len` bytes.
 * @param[in]     buf    Datagram.
 * @param[in]     len    Its length.
 * @param[out]    frame  Decoded frame (meaningless when refused).
 * @param[in,out] msg    Unpack buffer, initialised once with msgpack_unpacked_init() and reused.
 * @return 1 for an accepted data frame, 0 when refused.
 */
int gl_can_udp_decode(const char *buf, size_t len, gl_can_frame_t *frame, msgpack_unpacked *msg);

/** Room for one encoded frame (a 64-byte FD payload and the ten keys take about 190 bytes). */
#define GL_CAN_UDP_MAX_DATAGRAM 256

/**
 * @brief Encode a frame as python-can's udp_multicast sends it (a msgpack map of ten keys).
 * @param[in]  frame      Frame.
 * @param[in]  timestamp  Seconds (the `timestamp` key).
 * @param[out] buf        Output.
 * @param[in]  cap        Its size.
 * @return Bytes written, 0 when `cap` is too small.
 */
size_t gl_can_udp_encode(const gl_can_frame_t *frame, double timestamp, char *buf, size_t cap);

#endif /* GAINLINK_GL_CAN_UDP_H */
