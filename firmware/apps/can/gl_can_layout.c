/**
 * @file gl_can_layout.c
 * @brief Encoding and decoding of the gainlink CAN layout (explicit little-endian byte order).
 *
 * The int16 quantisation is done in double with rint() (round half to even in the default rounding
 * mode), exactly as gainlink.hil.links.can_layout.quantise does in float64 with numpy.rint, so both sides
 * produce the same raw values bit for bit (built with -ffp-contract=off: no fused multiply-add).
 */
#include "gl_can_layout.h"

#include <math.h>
#include <string.h>

static const uint8_t fd_lengths[] = {8, 12, 16, 20, 24, 32, 48, 64};

_Static_assert(GL_CAN_CLASSIC_HEADER <= 8u && GL_CAN_FD_HEADER <= 8u, "a header is one 64-bit word");
_Static_assert(GL_CAN_FD_MAX_FRAME <= GL_CAN_MAX_DATA, "an FD frame fits gl_can_frame_t");

void gl_can_layout_init(gl_can_layout_t *layout, uint32_t base_id, int fd, gl_can_encoding_t encoding)
{
    layout->base_id = base_id;
    layout->fd = fd ? 1 : 0;
    layout->encoding = encoding == GL_CAN_INT16 ? GL_CAN_INT16 : GL_CAN_FLOAT32;
    layout->value_bytes = layout->encoding == GL_CAN_INT16 ? 2u : 4u;
    layout->header = fd ? GL_CAN_FD_HEADER : GL_CAN_CLASSIC_HEADER;
    layout->status_hi_start = fd ? GL_CAN_FD_STATUS_HI_START : GL_CAN_CLASSIC_STATUS_HI_START;
    layout->status_hi_bits = fd ? GL_CAN_FD_STATUS_HI_BITS : GL_CAN_CLASSIC_STATUS_HI_BITS;
    layout->sat_start = fd ? GL_CAN_FD_SAT_START : GL_CAN_CLASSIC_SAT_START;
    layout->sat_bits = fd ? GL_CAN_FD_SAT_BITS : GL_CAN_CLASSIC_SAT_BITS;
    layout->max_frame = fd ? GL_CAN_FD_MAX_FRAME : GL_CAN_CLASSIC_MAX_FRAME;
    /* one `sat` bit per value, within the largest frame (gainlink.shipping.flags.CanHeader.values) */
    const uint32_t room = (layout->max_frame - layout->header) / layout->value_bytes;
    layout->per_frame = room < layout->sat_bits ? room : layout->sat_bits;
}

uint32_t gl_can_layout_frames(const gl_can_layout_t *layout, uint32_t count)
{
    return (count + layout->per_frame - 1u) / layout->per_frame;
}

int16_t gl_can_quantise(float value, const gl_can_scale_t *scale, int *clipped)
{
    if (clipped != NULL) {
        *clipped = 0;
    }
    if (!isfinite(value)) {
        return (int16_t)GL_CAN_INT16_NAN;
    }
    double x = rint(((double)value - scale->offset) / scale->factor);
    if (x > (double)GL_CAN_INT16_MAX || x < -(double)GL_CAN_INT16_MAX) {
        if (clipped != NULL) {
            *clipped = 1;
        }
        x = x > 0.0 ? (double)GL_CAN_INT16_MAX : -(double)GL_CAN_INT16_MAX;
    }
    return (int16_t)x;
}

float gl_can_dequantise(int16_t raw, const gl_can_scale_t *scale)
{
    if (raw == GL_CAN_INT16_NAN) {
        return NAN;
    }
    return (float)((double)raw * scale->factor + scale->offset);
}

static uint32_t chunk(const gl_can_layout_t *layout, uint32_t index, uint32_t count)
{
    uint32_t first = index * layout->per_frame;
    uint32_t left = count > first ? count - first : 0u;
    return left < layout->per_frame ? left : layout->per_frame;
}

/** The `bits` low bits set (bits <= 32). */
static uint32_t low_bits(uint32_t bits)
{
    return bits >= 32u ? 0xFFFFFFFFu : (1u << bits) - 1u;
}

/** The header's fields as one word, written little-endian (gainlink.shipping.flags.CanHeader.pack). */
static void put_header(const gl_can_layout_t *layout, uint8_t *data, uint16_t seq, uint16_t status, uint32_t sat)
{
    const uint32_t hi = ((uint32_t)status >> 8) & low_bits(layout->status_hi_bits);
    const uint64_t word = (uint64_t)seq | ((uint64_t)(status & 0xFFu) << 16) |
                          ((uint64_t)hi << layout->status_hi_start) |
                          ((uint64_t)(sat & low_bits(layout->sat_bits)) << layout->sat_start);
    for (uint32_t b = 0; b < layout->header; ++b) {
        data[b] = (uint8_t)(word >> (8u * b));
    }
}

int gl_can_layout_header(const gl_can_layout_t *layout, const gl_can_frame_t *frame, uint16_t *seq, uint16_t *status,
                         uint32_t *sat)
{
    if (frame->len < layout->header) {
        return -1;
    }
    uint64_t word = 0;
    for (uint32_t b = 0; b < layout->header; ++b) {
        word |= (uint64_t)frame->data[b] << (8u * b);
    }
    *seq = (uint16_t)(word & 0xFFFFu);
    if (status != NULL) {
        const uint32_t hi = (uint32_t)(word >> layout->status_hi_start) & low_bits(layout->status_hi_bits);
        *status = (uint16_t)(((word >> 16) & 0xFFu) | (hi << 8));
    }
    if (sat != NULL) {
        *sat = (uint32_t)(word >> layout->sat_start) & low_bits(layout->sat_bits);
    }
    return 0;
}

static uint8_t frame_length(const gl_can_layout_t *layout, uint32_t values)
{
    uint32_t need = layout->header + layout->value_bytes * values;
    if (!layout->fd) {
        return 8u;
    }
    for (size_t i = 0; i < sizeof fd_lengths; ++i) {
        if (fd_lengths[i] >= need) {
            return fd_lengths[i];
        }
    }
    return 64u;
}

uint32_t gl_can_layout_encode(const gl_can_layout_t *layout, uint32_t id, uint32_t index, uint16_t seq,
                              uint16_t status, uint32_t sat, const float *values, const gl_can_scale_t *scales,
                              uint32_t count, gl_can_frame_t *frame)
{
    uint32_t k = chunk(layout, index, count);
    uint32_t first = index * layout->per_frame;
    uint32_t clipped = 0;
    memset(frame, 0, sizeof *frame);
    frame->id = id;
    frame->fd = (uint8_t)layout->fd;
    frame->len = frame_length(layout, k);
    /* this frame's values' saturation bits (a vector's mask has 32: none beyond) */
    const uint32_t frame_sat = first < 32u ? (sat >> first) & low_bits(k) : 0u;
    put_header(layout, frame->data, seq, status, frame_sat);
    for (uint32_t i = 0; i < k; ++i) {
        uint8_t *p = &frame->data[layout->header + layout->value_bytes * i];
        if (layout->encoding == GL_CAN_INT16) {
            int c = 0;
            uint16_t bits = (uint16_t)gl_can_quantise(values[first + i], &scales[first + i], &c);
            clipped += (uint32_t)c;
            p[0] = (uint8_t)(bits & 0xFFu);
            p[1] = (uint8_t)(bits >> 8);
        } else {
            uint32_t bits;
            memcpy(&bits, &values[first + i], sizeof bits);
            p[0] = (uint8_t)(bits & 0xFFu);
            p[1] = (uint8_t)((bits >> 8) & 0xFFu);
            p[2] = (uint8_t)((bits >> 16) & 0xFFu);
            p[3] = (uint8_t)(bits >> 24);
        }
    }
    return clipped;
}

int gl_can_layout_decode(const gl_can_layout_t *layout, uint32_t index, const gl_can_frame_t *frame, uint16_t *seq,
                         float *values, const gl_can_scale_t *scales, uint32_t count)
{
    uint32_t k = chunk(layout, index, count);
    uint32_t first = index * layout->per_frame;
    if (frame->len < layout->header + layout->value_bytes * k) {
        return -1;
    }
    (void)gl_can_layout_header(layout, frame, seq, NULL, NULL);
    for (uint32_t i = 0; i < k; ++i) {
        const uint8_t *p = &frame->data[layout->header + layout->value_bytes * i];
        if (layout->encoding == GL_CAN_INT16) {
            uint16_t bits = (uint16_t)(p[0] | ((uint16_t)p[1] << 8));
            int16_t raw;
            memcpy(&raw, &bits, sizeof raw);  /* two's complement reinterpretation, no implementation-defined cast */
            values[first + i] = gl_can_dequantise(raw, &scales[first + i]);
        } else {
            uint32_t bits = (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
            memcpy(&values[first + i], &bits, sizeof bits);
        }
    }
    return 0;
}
