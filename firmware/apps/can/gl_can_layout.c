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

void gl_can_layout_init(gl_can_layout_t *layout, uint32_t base_id, int fd, gl_can_encoding_t encoding)
{
    layout->base_id = base_id;
    layout->fd = fd ? 1 : 0;
    layout->encoding = encoding == GL_CAN_INT16 ? GL_CAN_INT16 : GL_CAN_FLOAT32;
    layout->value_bytes = layout->encoding == GL_CAN_INT16 ? 2u : 4u;
    layout->per_frame = fd ? GL_CAN_FD_VALUES : (8u - GL_CAN_HEADER) / layout->value_bytes;
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

static uint8_t frame_length(const gl_can_layout_t *layout, uint32_t values)
{
    uint32_t need = GL_CAN_HEADER + layout->value_bytes * values;
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
    frame->data[0] = (uint8_t)(seq & 0xFFu);
    frame->data[1] = (uint8_t)(seq >> 8);
    frame->data[2] = (uint8_t)(status & 0xFFu);
    frame->data[3] = (uint8_t)(((sat >> first) & ((1u << k) - 1u)) | (((status >> 8) & 0x0Fu) << GL_CAN_SAT_BITS));
    for (uint32_t i = 0; i < k; ++i) {
        uint8_t *p = &frame->data[GL_CAN_HEADER + layout->value_bytes * i];
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
    if (frame->len < GL_CAN_HEADER + layout->value_bytes * k) {
        return -1;
    }
    *seq = (uint16_t)(frame->data[0] | ((uint16_t)frame->data[1] << 8));
    for (uint32_t i = 0; i < k; ++i) {
        const uint8_t *p = &frame->data[GL_CAN_HEADER + layout->value_bytes * i];
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
