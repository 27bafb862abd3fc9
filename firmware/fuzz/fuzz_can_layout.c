/**
 * @file fuzz_can_layout.c
 * @brief libFuzzer harness: the CAN layout decoder (gl_can_layout_decode), float32 and int16, classic and FD.
 *
 * Input: byte 0 selects the layout (bit 0 int16, bit 1 FD), byte 1 the vector length (1..32) and byte 2 the
 * frame index; the rest is the frame payload (up to 64 bytes). Oracles besides ASan/UBSan: a frame is refused
 * exactly when it is shorter than its values need; decoding writes only this frame's slice of the vector; and
 * encoding the decoded values with the header's status and saturation bits (gl_can_layout_header) again reproduces
 * the header bit for bit (wire format 4: every header bit is a field; only the saturation bits of values beyond the
 * frame's are dropped) and the payload's value bytes (float32: the same bits, NaN payloads included; int16: the same
 * raw values, with the scales of a DBC range of +-5).
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "gl_can_layout.h"

#define MAX_VALUES 32u /* three FD frames of float32 values, two of int16 */

static const float sentinel = 12345.678f;

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 3u) {
        return 0;
    }
    gl_can_layout_t layout;
    const gl_can_encoding_t enc = (data[0] & 1u) ? GL_CAN_INT16 : GL_CAN_FLOAT32;
    gl_can_layout_init(&layout, 0x100u, (data[0] >> 1) & 1u, enc);
    const uint32_t count = 1u + data[1] % MAX_VALUES;
    const uint32_t frames = gl_can_layout_frames(&layout, count);
    const uint32_t index = data[2] % frames;
    gl_can_frame_t frame;
    memset(&frame, 0, sizeof frame);
    frame.len = (uint8_t)((size - 3u) > GL_CAN_MAX_DATA ? GL_CAN_MAX_DATA : (size - 3u));
    frame.fd = (uint8_t)layout.fd;
    memcpy(frame.data, &data[3], frame.len);

    gl_can_scale_t scales[MAX_VALUES];
    for (uint32_t i = 0; i < MAX_VALUES; ++i) {
        scales[i].factor = 10.0 / 65534.0; /* range [-5, 5] as gainlink.hil.links.can_layout derives it */
        scales[i].offset = 0.0;
    }
    float values[MAX_VALUES];
    for (uint32_t i = 0; i < MAX_VALUES; ++i) {
        values[i] = sentinel;
    }
    uint16_t seq = 0;
    const uint32_t first = index * layout.per_frame;
    const uint32_t k = count - first < layout.per_frame ? count - first : layout.per_frame;
    const int too_short = frame.len < layout.header + layout.value_bytes * k;
    const int rc = gl_can_layout_decode(&layout, index, &frame, &seq, values, scales, count);
    if ((rc != 0) != too_short) {
        abort();
    }
    for (uint32_t i = 0; i < MAX_VALUES; ++i) {
        const int inside = rc == 0 && i >= first && i < first + k;
        if (!inside && memcmp(&values[i], &sentinel, sizeof sentinel) != 0) {
            abort(); /* written outside this frame's slice */
        }
    }
    if (rc != 0) {
        return 0;
    }
    uint16_t hseq = 0, status = 0;
    uint32_t sat = 0;
    if (gl_can_layout_header(&layout, &frame, &hseq, &status, &sat) != 0 || hseq != seq) {
        abort();
    }
    gl_can_frame_t again;
    const uint32_t kept = sat & (k >= 32u ? 0xFFFFFFFFu : (1u << k) - 1u); /* the frame's values' bits */
    (void)gl_can_layout_encode(&layout, frame.id, index, seq, status, kept << first, values, scales, count, &again);
    uint16_t wseq = 0, wstatus = 0;
    uint32_t wsat = 0;
    (void)gl_can_layout_header(&layout, &again, &wseq, &wstatus, &wsat);
    if (wseq != seq || wstatus != status || wsat != kept) {
        abort(); /* the header's fields do not survive a round trip */
    }
    if (kept == sat && memcmp(again.data, frame.data, layout.header) != 0) {
        abort(); /* every header bit is a field: the same fields make the same bytes */
    }
    if (memcmp(&again.data[layout.header], &frame.data[layout.header], layout.value_bytes * k) != 0) {
        abort();
    }
    return 0;
}
