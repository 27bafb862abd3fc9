/**
 * @file gl_can_layout.h
 * @brief The CAN layout of the artifact's samples and commands (the rule of gainlink.hil.can_layout).
 *
 * Every frame: bytes 0-1 `seq` (uint16 LE), byte 2 `status`, byte 3 `sat` (bit i: i-th value of this
 * frame saturated), then float32 LE values: 1 per classic frame (8 bytes), up to 8 per FD frame
 * (length rounded up to a valid FD length). Commands (u) use ids base+j; measurements (y then r)
 * use ids base+0x10+i.
 */
#ifndef GAINLINK_GL_CAN_LAYOUT_H
#define GAINLINK_GL_CAN_LAYOUT_H

#include <stdint.h>

#include "gl_can_link.h"

#define GL_CAN_HEADER 4u                /**< Header bytes. */
#define GL_CAN_FD_VALUES 8u             /**< Values per FD frame. */
#define GL_CAN_CMD_OFFSET 0x00u         /**< Command ids: base + this + frame index. */
#define GL_CAN_MEAS_OFFSET 0x10u        /**< Measurement ids: base + this + frame index. */
#define GL_CAN_STATUS_FAULT 0x01u       /**< Command status: non-finite sample refused. */
#define GL_CAN_STATUS_WATCHDOG 0x02u    /**< Command status: watchdog expired. */

/** Layout parameters. */
typedef struct gl_can_layout {
    uint32_t base_id;    /**< First identifier. */
    int fd;              /**< CAN FD. */
    uint32_t per_frame;  /**< Values per frame. */
} gl_can_layout_t;

/**
 * @brief Fill a layout.
 * @param[out] layout   Layout.
 * @param[in]  base_id  First identifier.
 * @param[in]  fd       CAN FD.
 */
void gl_can_layout_init(gl_can_layout_t *layout, uint32_t base_id, int fd);

/**
 * @brief Number of frames that carry `count` values.
 * @param[in] layout Layout. @param[in] count Values.
 * @return Frames.
 */
uint32_t gl_can_layout_frames(const gl_can_layout_t *layout, uint32_t count);

/**
 * @brief Encode frame `index` of a vector of `count` values.
 * @param[in]  layout  Layout.
 * @param[in]  id      Arbitration id of the frame.
 * @param[in]  index   Frame index.
 * @param[in]  seq     Sequence number.
 * @param[in]  status  Status byte.
 * @param[in]  sat     Saturation mask of the whole vector (bit k: value k).
 * @param[in]  values  The vector.
 * @param[in]  count   Its length.
 * @param[out] frame   Encoded frame.
 */
void gl_can_layout_encode(const gl_can_layout_t *layout, uint32_t id, uint32_t index, uint16_t seq, uint8_t status,
                          uint32_t sat, const float *values, uint32_t count, gl_can_frame_t *frame);

/**
 * @brief Decode frame `index` of a vector of `count` values into `values`.
 * @param[in]  layout  Layout.
 * @param[in]  index   Frame index.
 * @param[in]  frame   Frame.
 * @param[out] seq     Its sequence number.
 * @param[out] values  The vector (only this frame's slice is written).
 * @param[in]  count   Vector length.
 * @return 0, or -1 when the frame is too short.
 */
int gl_can_layout_decode(const gl_can_layout_t *layout, uint32_t index, const gl_can_frame_t *frame, uint16_t *seq,
                         float *values, uint32_t count);

#endif /* GAINLINK_GL_CAN_LAYOUT_H */
