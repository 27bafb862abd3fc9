/**
 * @file gl_can_layout.c
 * @brief Encoding and decoding of the gainlink CAN layout (explicit little-endian byte order).
 */
#include "gl_can_layout.h"

#include <string.h>

static const uint8_t fd_lengths[] = {8, 12, 16, 20, 24, 32, 48, 64};

void gl_can_layout_init(gl_can_layout_t *layout, uint32_t base_id, int fd)
{
    layout->base_id = base_id;
    layout->fd = fd ? 1 : 0;
    layout->per_frame = fd ? GL_CAN_FD_VALUES : 1u;
}

uint32_t gl_can_layout_frames(const gl_can_layout_t *layout, uint32_t count)
{
    return (count + layout->per_frame - 1u) / layout->per_frame;
}

static uint32_t chunk(const gl_can_layout_t *layout, uint32_t index, uint32_t count)
{
    uint32_t first = index * layout->per_frame;
    uint32_t left = count > first ? count - first : 0u;
    return left < layout->per_frame ? left : layout->per_frame;
}

static uint8_t frame_length(const gl_can_layout_t *layout, uint32_t values)
{
    uint32_t need = GL_CAN_HEADER + 4u * values;
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

void gl_can_layout_encode(const gl_can_layout_t *layout, uint32_t id, uint32_t index, uint16_t seq, uint8_t status,
                          uint32_t sat, const float *values, uint32_t count, gl_can_frame_t *frame)
{
    uint32_t k = chunk(layout, index, count);
    uint32_t first = index * layout->per_frame;
    memset(frame, 0, sizeof *frame);
    frame->id = id;
    frame->fd = (uint8_t)layout->fd;
    frame->len = frame_length(layout, k);
    frame->data[0] = (uint8_t)(seq & 0xFFu);
    frame->data[1] = (uint8_t)(seq >> 8);
    frame->data[2] = status;
    frame->data[3] = (uint8_t)((sat >> first) & ((1u << k) - 1u));
    for (uint32_t i = 0; i < k; ++i) {
        uint32_t bits;
        memcpy(&bits, &values[first + i], sizeof bits);
        uint8_t *p = &frame->data[GL_CAN_HEADER + 4u * i];
        p[0] = (uint8_t)(bits & 0xFFu);
        p[1] = (uint8_t)((bits >> 8) & 0xFFu);
        p[2] = (uint8_t)((bits >> 16) & 0xFFu);
        p[3] = (uint8_t)(bits >> 24);
    }
}

int gl_can_layout_decode(const gl_can_layout_t *layout, uint32_t index, const gl_can_frame_t *frame, uint16_t *seq,
                         float *values, uint32_t count)
{
    uint32_t k = chunk(layout, index, count);
    uint32_t first = index * layout->per_frame;
    if (frame->len < GL_CAN_HEADER + 4u * k) {
        return -1;
    }
    *seq = (uint16_t)(frame->data[0] | ((uint16_t)frame->data[1] << 8));
    for (uint32_t i = 0; i < k; ++i) {
        const uint8_t *p = &frame->data[GL_CAN_HEADER + 4u * i];
        uint32_t bits = (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
        memcpy(&values[first + i], &bits, sizeof bits);
    }
    return 0;
}
