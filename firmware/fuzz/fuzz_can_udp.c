/**
 * @file fuzz_can_udp.c
 * @brief libFuzzer harness: the udp_multicast datagram decoder (gl_can_udp_decode).
 *
 * Oracles besides ASan/UBSan: an accepted frame is a standard data frame that fits its kind (id <= 0x7FF,
 * at most 8 bytes unless FD, at most 64), and encoding it as the app sends it and decoding that again gives
 * the same frame back.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "gl_can_udp.h"

static msgpack_unpacked msg;
static int msg_ready;

static void check_round_trip(const gl_can_frame_t *frame)
{
    char buf[GL_CAN_UDP_MAX_DATAGRAM];
    size_t len = gl_can_udp_encode(frame, 1.5, buf, sizeof buf);
    if (len == 0u) {
        abort(); /* every acceptable frame fits the datagram buffer */
    }
    gl_can_frame_t again;
    if (gl_can_udp_decode(buf, len, &again, &msg) != 1 || again.id != frame->id || again.len != frame->len ||
        again.fd != frame->fd || memcmp(again.data, frame->data, frame->len) != 0) {
        abort();
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (!msg_ready) {
        msgpack_unpacked_init(&msg);
        msg_ready = 1;
    }
    gl_can_frame_t frame;
    if (gl_can_udp_decode((const char *)data, size, &frame, &msg) != 1) {
        return 0;
    }
    if (frame.id > 0x7FFu || frame.len > GL_CAN_MAX_DATA || (!frame.fd && frame.len > 8u)) {
        abort();
    }
    check_round_trip(&frame);
    return 0;
}
