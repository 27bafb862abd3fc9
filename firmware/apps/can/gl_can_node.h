/**
 * @file gl_can_node.h
 * @brief The CAN node of the loop, independent of its link: frames in, frames out.
 *
 * Assembles each sample (y, r, then a scheduled law's external scheduling signals) from its measurement frames by
 * sequence number, steps the build's law (gl_law.h) once per complete, newer sample (duplicates and stale samples
 * are ignored and counted), and answers with the command frames carrying the same sequence number, the step's
 * status flags (GL_FLAG_* of the one flag table: the status byte) and the saturation mask (layout in
 * gl_can_layout.h). It steps only on a sample: it has no idle period, so it never sends the watchdog bit. The host app `gainlink_can` feeds it from SocketCAN or udp_multicast,
 * the Cortex-M4F image from slcan on its UART (gl_slcan.h).
 */
#ifndef GAINLINK_GL_CAN_NODE_H
#define GAINLINK_GL_CAN_NODE_H

#include <stdint.h>

#include "gainlink/gl_law.h"
#include "gl_can_layout.h"
#include "gl_can_link.h"

/** Values of one sample: the outputs, then the references (then a scheduled law's external signals). */
#define GL_CAN_NODE_SAMPLE ((uint32_t)(GL_P + GL_Q + GL_LAW_E))
/** Array length of a sample (GL_QA: no zero-length arrays). */
#define GL_CAN_NODE_SAMPLE_A (GL_P + GL_QA + GL_LAW_E)

/** What the node reports through gl_can_node_config_t::event. */
typedef enum gl_can_node_event {
    GL_CAN_EV_SHORT_FRAME = 0, /**< A measurement frame too short for its values (ignored). */
    GL_CAN_EV_SEND_FAILED = 1  /**< send() refused a command frame (errno as send() left it). */
} gl_can_node_event_t;

/** Node configuration. */
typedef struct gl_can_node_config {
    uint32_t base_id;                        /**< First identifier (commands base+j, samples base+0x10+i). */
    int fd;                                  /**< CAN FD frames. */
    gl_can_encoding_t encoding;              /**< Value encoding. */
    gl_can_scale_t meas_scale[GL_CAN_NODE_SAMPLE_A]; /**< int16: factor and offset of each sample value. */
    gl_can_scale_t cmd_scale[GL_M];          /**< int16: factor and offset of each command value. */
    uint32_t watchdog_periods;               /**< Idle periods before the law's safe command. */
    void *ctx;                               /**< Passed back to send(). */
    /** Send one command frame; 0 when sent or queued, -1 when it could not be. */
    int (*send)(void *ctx, const gl_can_frame_t *frame);
    /** Event hook (NULL: none); must not block. */
    void (*event)(void *ctx, gl_can_node_event_t event, const gl_can_frame_t *frame);
} gl_can_node_config_t;

/** Counters (saturating). */
typedef struct gl_can_node_stats {
    uint32_t used;            /**< Measurement frames decoded (stale ones included). */
    uint32_t short_frames;    /**< Measurement frames too short for their values. */
    uint32_t steps;           /**< Samples stepped and answered. */
    uint32_t stale;           /**< Frames of a sample already answered or older. */
    uint32_t partial_dropped; /**< Samples abandoned with some of their frames missing. */
    uint32_t send_errors;     /**< Command frames send() refused. */
    uint32_t foreign;         /**< Frames outside the measurement identifiers. */
    uint32_t clipped;         /**< int16 command values beyond their range, sent saturated. */
} gl_can_node_stats_t;

/** The node (holds the loop: give it static storage). */
typedef struct gl_can_node {
    gl_can_node_config_t cfg;          /**< Configuration. */
    gl_can_layout_t layout;            /**< Frame layout. */
    gl_law_t loop;                     /**< The control law (gl_law.h). */
    gl_can_node_stats_t stats;         /**< Counters. */
    uint32_t meas_base;                /**< First measurement identifier. */
    uint32_t meas_frames;              /**< Frames per sample. */
    uint32_t cmd_frames;               /**< Frames per command. */
    float sample[GL_CAN_NODE_SAMPLE_A];        /**< Sample being assembled. */
    uint32_t got;                      /**< Frames of it received (bit per frame). */
    uint16_t cur_seq;                  /**< Its sequence number. */
    uint16_t last_done;                /**< Sequence number last answered. */
    int have_cur;                      /**< A sample is being assembled. */
    int have_done;                     /**< Some sample was answered. */
} gl_can_node_t;

/**
 * @brief Initialise the node and its law on the compiled gain set.
 * @param[out] node Node.
 * @param[in]  cfg  Configuration (copied).
 * @return GL_OK, or the loop's refusal of the compiled gains.
 */
gl_status_t gl_can_node_init(gl_can_node_t *node, const gl_can_node_config_t *cfg);

/**
 * @brief Handle one received frame.
 * @param[in,out] node  Node.
 * @param[in]     frame Frame (any identifier; foreign ones are counted and ignored).
 * @return 1 when it completed a sample (stepped and answered), else 0.
 */
int gl_can_node_frame(gl_can_node_t *node, const gl_can_frame_t *frame);

/**
 * @brief The identifiers the node listens to (for a link's receive filter).
 * @param[in]  node Node.
 * @param[out] lo   Lowest measurement identifier.
 * @param[out] hi   Highest measurement identifier.
 */
void gl_can_node_rx_range(const gl_can_node_t *node, uint32_t *lo, uint32_t *hi);

#endif /* GAINLINK_GL_CAN_NODE_H */
