/**
 * @file gl_slcan.h
 * @brief slcan (Lawicel ASCII) adapter side, independent of the serial link: bytes in, frames out.
 *
 * What a USB-CAN adapter speaks on its serial port, so `can.Bus(interface="slcan", channel=...)`
 * (python-can, or Linux slcand) talks to the node as to an adapter. Commands end with CR (LF is ignored);
 * every answer ends with CR (`\r`, OK) or BEL (`\a`, refused):
 *
 * | command | answer |
 * | --- | --- |
 * | `Sn` (n 0..8), `sxxyy` bit rate | CR when closed, BEL when open |
 * | `O` open, `L` open listen-only | CR (BEL when already open) |
 * | `C` close | CR |
 * | `tiiildd..` standard data frame (iii hex id, l 0..8 bytes) | `z` CR when open and well formed, else BEL |
 * | `Tiiiiiiiildd..` extended data frame | `Z` CR (accepted and not delivered: the node uses 11-bit ids) |
 * | `riiil`, `Riiiiiiiil` remote frames | `z`/`Z` CR, not delivered |
 * | `V` `N` `F` | `V1013`, `NGL00`, `Fxx` (bit 3: receive overrun since the last `F`) |
 * | `Z0` | CR (`Z1`, time stamps, BEL) |
 * | CAN FD (`d` `D` `b` `B`), anything else, a line longer than a frame | BEL |
 *
 * Frames from the node go out as `tiiildd..` CR while open (dropped and counted while closed).
 * CAN FD is not part of slcan: use classic frames (the float32 or int16 layout of gl_can_layout.h).
 */
#ifndef GAINLINK_GL_SLCAN_H
#define GAINLINK_GL_SLCAN_H

#include <stddef.h>
#include <stdint.h>

#include "gl_can_link.h"

/** Longest accepted line without its CR: `T` + 8 id digits + length + 16 data digits. */
#define GL_SLCAN_LINE_MAX 26u

/** What the adapter needs from its serial link and its node. */
typedef struct gl_slcan_port {
    void *ctx; /**< Passed back to every function. */
    /** Write answer bytes; 0 when written or queued, -1 when dropped. Required. */
    int (*write)(void *ctx, const uint8_t *bytes, size_t len);
    /** A standard data frame arrived while open. Required. */
    void (*frame)(void *ctx, const gl_can_frame_t *frame);
    /** Receive overruns of the serial link so far (NULL: none), reported by `F`. */
    uint32_t (*overruns)(void *ctx);
} gl_slcan_port_t;

/** Counters (saturating). */
typedef struct gl_slcan_stats {
    uint32_t frames_in;   /**< Standard data frames delivered. */
    uint32_t frames_out;  /**< Frames sent. */
    uint32_t refused;     /**< Lines answered with BEL (unknown, malformed, wrong state, too long). */
    uint32_t not_sent;    /**< Frames the node sent while closed, or that the link could not take. */
} gl_slcan_stats_t;

/** The adapter state. */
typedef struct gl_slcan {
    gl_slcan_port_t port;              /**< Link and node. */
    gl_slcan_stats_t stats;            /**< Counters. */
    char line[GL_SLCAN_LINE_MAX];      /**< Line being received. */
    uint32_t len;                      /**< Its length. */
    int overlong;                      /**< The line outgrew `line` (refused at its CR). */
    int open;                          /**< Channel open (`O` or `L`). */
    int listen_only;                   /**< Opened with `L`: frames are not sent. */
    uint32_t overruns_seen;            /**< Overruns already reported by `F`. */
} gl_slcan_t;

/**
 * @brief Initialise (closed).
 * @param[out] s    Adapter.
 * @param[in]  port Link and node (copied).
 */
void gl_slcan_init(gl_slcan_t *s, const gl_slcan_port_t *port);

/**
 * @brief Feed received serial bytes (any split); commands are answered and frames delivered as lines end.
 * @param[in,out] s     Adapter.
 * @param[in]     bytes Bytes.
 * @param[in]     len   Their number.
 */
void gl_slcan_input(gl_slcan_t *s, const uint8_t *bytes, size_t len);

/**
 * @brief Send a classic standard data frame (`tiiildd..` CR).
 * @param[in,out] s     Adapter.
 * @param[in]     frame Frame (id <= 0x7FF, len <= 8, not FD).
 * @return 0 sent, -1 not sent (closed, listen-only, not a classic standard frame, or the link refused).
 */
int gl_slcan_send(gl_slcan_t *s, const gl_can_frame_t *frame);

#endif /* GAINLINK_GL_SLCAN_H */
