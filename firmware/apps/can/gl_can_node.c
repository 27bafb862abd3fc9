/**
 * @file gl_can_node.c
 * @brief Sample assembly, step and command frames of the CAN node (see gl_can_node.h).
 */
#include "gl_can_node.h"

#include <string.h>

static void inc(uint32_t *counter, uint32_t by)
{
    *counter = (*counter > UINT32_MAX - by) ? UINT32_MAX : *counter + by;
}

static void event(const gl_can_node_t *node, gl_can_node_event_t ev, const gl_can_frame_t *frame)
{
    if (node->cfg.event != NULL) {
        node->cfg.event(node->cfg.ctx, ev, frame);
    }
}

gl_status_t gl_can_node_init(gl_can_node_t *node, const gl_can_node_config_t *cfg)
{
    memset(node, 0, sizeof *node);
    node->cfg = *cfg;
    gl_can_layout_init(&node->layout, cfg->base_id, cfg->fd, cfg->encoding);
    node->meas_frames = gl_can_layout_frames(&node->layout, GL_CAN_NODE_SAMPLE);
    node->cmd_frames = gl_can_layout_frames(&node->layout, GL_M);
    node->meas_base = cfg->base_id + GL_CAN_MEAS_OFFSET;
    return gl_law_init(&node->loop, cfg->watchdog_periods);
}

void gl_can_node_rx_range(const gl_can_node_t *node, uint32_t *lo, uint32_t *hi)
{
    *lo = node->meas_base;
    *hi = node->meas_base + node->meas_frames - 1u;
}

/** Step the assembled sample and send the command frames. */
static void answer(gl_can_node_t *node, uint16_t seq)
{
    const float *r = GL_Q > 0 ? &node->sample[GL_P] : NULL;
    const float *s = GL_LAW_E > 0 ? &node->sample[GL_P + GL_Q] : NULL;
    gl_law_out_t out;
    (void)gl_law_step(&node->loop, node->sample, r, s, &out);
    /* the flags' bits 0-15: the header carries those it has room for (wire format 4, gl_can_layout.h) */
    const uint16_t status = (uint16_t)(out.flags & 0xFFFFu);
    uint32_t cmd_base = node->cfg.base_id + GL_CAN_CMD_OFFSET;
    for (uint32_t j = 0; j < node->cmd_frames; ++j) {
        gl_can_frame_t frame;
        inc(&node->stats.clipped, gl_can_layout_encode(&node->layout, cmd_base + j, j, seq, status, out.sat, out.u,
                                                       node->cfg.cmd_scale, GL_M, &frame));
        if (node->cfg.send(node->cfg.ctx, &frame) != 0) {
            inc(&node->stats.send_errors, 1u);
            event(node, GL_CAN_EV_SEND_FAILED, &frame);
        }
    }
    node->last_done = seq;
    node->have_done = 1;
    node->have_cur = 0;
    node->got = 0;
    inc(&node->stats.steps, 1u);
}

int gl_can_node_frame(gl_can_node_t *node, const gl_can_frame_t *frame)
{
    if (frame->id < node->meas_base || frame->id >= node->meas_base + node->meas_frames) {
        inc(&node->stats.foreign, 1u);
        return 0;
    }
    uint32_t index = frame->id - node->meas_base;
    uint16_t seq = 0;
    float part[GL_CAN_NODE_SAMPLE_A];
    if (gl_can_layout_decode(&node->layout, index, frame, &seq, part, node->cfg.meas_scale, GL_CAN_NODE_SAMPLE) != 0) {
        inc(&node->stats.short_frames, 1u);
        event(node, GL_CAN_EV_SHORT_FRAME, frame);
        return 0;
    }
    inc(&node->stats.used, 1u);
    if (node->have_done) {
        uint16_t ahead = (uint16_t)(seq - node->last_done);
        if (ahead == 0u || ahead >= 0x8000u) {
            inc(&node->stats.stale, 1u);
            return 0;
        }
    }
    if (!node->have_cur || seq != node->cur_seq) {
        if (node->have_cur && node->got != 0u) {
            inc(&node->stats.partial_dropped, 1u);
        }
        node->cur_seq = seq;
        node->have_cur = 1;
        node->got = 0;
    }
    uint32_t first = index * node->layout.per_frame;
    for (uint32_t i = first; i < first + node->layout.per_frame && i < GL_CAN_NODE_SAMPLE; ++i) {
        node->sample[i] = part[i];
    }
    node->got |= 1u << index;
    const uint32_t all = (node->meas_frames >= 32u) ? 0xFFFFFFFFu : ((1u << node->meas_frames) - 1u);
    if (node->got != all) {
        return 0;
    }
    answer(node, seq);
    return 1;
}
