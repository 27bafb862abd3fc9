/**
 * @file gl_can_layout.h
 * @brief The CAN layout of the artifact's samples and commands (the rule of gainlink.hil.links.can_layout).
 *
 * Every frame (wire format 4) starts with a header: bytes 0-1 `seq` (uint16 LE), byte 2 `status` (a command's:
 * bits 0-7 of the step's GL_FLAG_* of gl_flags.h, the one flag table; the DBC's value table of `status` is the same
 * table), then `status_hi` (the flags' bits 8 and up: CAPPED is its bit 0) and `sat` (bit i: i-th value of this
 * frame saturated) where gl_flags.h's GL_CAN_CLASSIC_* / GL_CAN_FD_* put them (generated from
 * gainlink.shipping.flags.CanHeader, as the DBC and the Python codec are):
 * - classic frames, 4 bytes: byte 3's low nibble `sat`, its high nibble `status_hi` (the flags' bits 8-11);
 * - CAN FD frames, 8 bytes: byte 3 `status_hi` (the flags' bits 8-15), bytes 4-7 `sat` (uint32 LE).
 * Then the values, little-endian, in one of two encodings:
 * - GL_CAN_FLOAT32: IEEE float32, 1 per classic frame (8 bytes), up to 14 per FD frame;
 * - GL_CAN_INT16: scaled integers, `physical = raw * factor + offset` with a factor and offset per value
 *   (gl_can_scale_t, from the DBC), 2 per classic frame, up to 28 per FD frame. Encoding computes
 *   `rint((value - offset) / factor)` in double (round half to even, as Python's numpy.rint and cantools),
 *   saturates to +-32767 and sends a non-finite value as -32768, which decodes to NaN.
 *
 * FD frame lengths are rounded up to a valid FD length. Commands (u) use ids base+j; measurements
 * (y then r) use ids base+0x10+i.
 */
#ifndef GAINLINK_GL_CAN_LAYOUT_H
#define GAINLINK_GL_CAN_LAYOUT_H

#include <stdint.h>

#include "gl_can_link.h"
#include "gl_flags.h" /* GL_CAN_CLASSIC_* and GL_CAN_FD_*: the headers' fields (wire format 4) */

#define GL_CAN_CMD_OFFSET 0x00u         /**< Command ids: base + this + frame index. */
#define GL_CAN_MEAS_OFFSET 0x10u        /**< Measurement ids: base + this + frame index. */
#define GL_CAN_INT16_MAX 32767          /**< Largest raw int16 value (-GL_CAN_INT16_MAX is the smallest). */
#define GL_CAN_INT16_NAN (-32768)       /**< Reserved raw int16 value: not a number. */

/** How values are carried. */
typedef enum gl_can_encoding {
    GL_CAN_FLOAT32 = 0,  /**< IEEE float32. */
    GL_CAN_INT16 = 1     /**< Scaled signed 16-bit integers. */
} gl_can_encoding_t;

/** The linear map of one int16 value: `physical = raw * factor + offset`. */
typedef struct gl_can_scale {
    double factor;  /**< Physical units per raw step (> 0). */
    double offset;  /**< Physical value of raw 0. */
} gl_can_scale_t;

/** Layout parameters. */
typedef struct gl_can_layout {
    uint32_t base_id;             /**< First identifier. */
    int fd;                       /**< CAN FD. */
    gl_can_encoding_t encoding;   /**< Value encoding. */
    uint32_t per_frame;           /**< Values per frame. */
    uint32_t value_bytes;         /**< Bytes per value (4 or 2). */
    uint32_t header;              /**< Header bytes (GL_CAN_CLASSIC_HEADER or GL_CAN_FD_HEADER). */
    uint32_t status_hi_start;     /**< Bit of the header where the flags' bit 8 sits. */
    uint32_t status_hi_bits;      /**< The flags' bits 8.. the header carries. */
    uint32_t sat_start;           /**< Bit of the header where the frame's saturation bits start. */
    uint32_t sat_bits;            /**< Saturation bits of the header. */
    uint32_t max_frame;           /**< Largest frame (8 or 64 bytes). */
} gl_can_layout_t;

/**
 * @brief Fill a layout.
 * @param[out] layout    Layout.
 * @param[in]  base_id   First identifier.
 * @param[in]  fd        CAN FD.
 * @param[in]  encoding  Value encoding.
 */
void gl_can_layout_init(gl_can_layout_t *layout, uint32_t base_id, int fd, gl_can_encoding_t encoding);

/**
 * @brief Number of frames that carry `count` values.
 * @param[in] layout Layout. @param[in] count Values.
 * @return Frames.
 */
uint32_t gl_can_layout_frames(const gl_can_layout_t *layout, uint32_t count);

/**
 * @brief Raw int16 value of a physical value.
 * @param[in]  value    Physical value.
 * @param[in]  scale    Its factor and offset.
 * @param[out] clipped  Set to 1 when a finite value was beyond the range and saturated, else 0 (may be NULL).
 * @return `rint((value - offset) / factor)` in double, clamped to +-GL_CAN_INT16_MAX; GL_CAN_INT16_NAN
 *         for a non-finite value.
 */
int16_t gl_can_quantise(float value, const gl_can_scale_t *scale, int *clipped);

/**
 * @brief Physical value of a raw int16 value.
 * @param[in] raw    Raw value.
 * @param[in] scale  Its factor and offset.
 * @return `(float)(raw * factor + offset)` computed in double; NaN for GL_CAN_INT16_NAN.
 */
float gl_can_dequantise(int16_t raw, const gl_can_scale_t *scale);

/**
 * @brief Encode frame `index` of a vector of `count` values.
 * @param[in]  layout  Layout.
 * @param[in]  id      Arbitration id of the frame.
 * @param[in]  index   Frame index.
 * @param[in]  seq     Sequence number.
 * @param[in]  status  Status flags: bits 0-7 go to byte 2, bits 8.. to `status_hi` (those beyond it are dropped).
 * @param[in]  sat     Saturation mask of the whole vector (bit k: value k).
 * @param[in]  values  The vector.
 * @param[in]  scales  Per value factor and offset (GL_CAN_INT16; ignored, may be NULL, for GL_CAN_FLOAT32).
 * @param[in]  count   Its length.
 * @param[out] frame   Encoded frame.
 * @return Number of values of this frame that were beyond their range and saturated (0 with float32).
 */
uint32_t gl_can_layout_encode(const gl_can_layout_t *layout, uint32_t id, uint32_t index, uint16_t seq,
                              uint16_t status, uint32_t sat, const float *values, const gl_can_scale_t *scales,
                              uint32_t count, gl_can_frame_t *frame);

/**
 * @brief Read a frame's header.
 * @param[in]  layout  Layout.
 * @param[in]  frame   Frame.
 * @param[out] seq     Its sequence number.
 * @param[out] status  Its status flags (bits 0-7 and `status_hi`; may be NULL).
 * @param[out] sat     Its saturation bits (bit i: the frame's i-th value; may be NULL).
 * @return 0, or -1 when the frame is shorter than the header.
 */
int gl_can_layout_header(const gl_can_layout_t *layout, const gl_can_frame_t *frame, uint16_t *seq, uint16_t *status,
                         uint32_t *sat);

/**
 * @brief Decode frame `index` of a vector of `count` values into `values`.
 * @param[in]  layout  Layout.
 * @param[in]  index   Frame index.
 * @param[in]  frame   Frame.
 * @param[out] seq     Its sequence number.
 * @param[out] values  The vector (only this frame's slice is written).
 * @param[in]  scales  Per value factor and offset (GL_CAN_INT16; ignored, may be NULL, for GL_CAN_FLOAT32).
 * @param[in]  count   Vector length.
 * @return 0, or -1 when the frame is too short.
 */
int gl_can_layout_decode(const gl_can_layout_t *layout, uint32_t index, const gl_can_frame_t *frame, uint16_t *seq,
                         float *values, const gl_can_scale_t *scales, uint32_t count);

#endif /* GAINLINK_GL_CAN_LAYOUT_H */
