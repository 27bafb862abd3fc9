/**
 * @file gl_mav_node.h
 * @brief The MAVLink node of the control loop, independent of its transport: bytes in, bytes out.
 *
 * One node holds the loop (::gl_loop_t), its parameter table and the MAVLink parse state of one
 * channel. Whatever carries the bytes (UDP on the host, a UART on the Cortex-M image, a fuzz harness)
 * feeds them to gl_mav_node_input() and gets the answers through ::gl_mav_port_t::send. It speaks:
 *
 * - HEARTBEAT at 1 Hz (gl_mav_node_poll()) and on demand (gl_mav_node_heartbeat(), e.g. to a new peer):
 *   MAV_TYPE_GENERIC, MAV_AUTOPILOT_GENERIC.
 * - AUTOPILOT_VERSION on MAV_CMD_REQUEST_MESSAGE(148) or MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
 *   capabilities MAVLINK2 | PARAM_ENCODE_BYTEWISE, flight_custom_version = first 8 hex digits of the
 *   artifact's sha256, uid = CRC-32 of the committed gain set.
 * - SYS_STATUS on MAV_CMD_REQUEST_MESSAGE(1): the link's error counters (see gl_mav_node_stats_t).
 * - The parameter protocol over the gain set (naming in gl_mav_params.h): PARAM_REQUEST_LIST (streamed as
 *   the transport has room), PARAM_REQUEST_READ by id or index (PARAM_ERROR when unknown), PARAM_SET
 *   always answered with PARAM_VALUE (the value now held), then PARAM_ERROR when refused.
 * - MAV_CMD_PREFLIGHT_STORAGE param1 = 0 reload from storage, 1 write the committed set to it, 2 reset to
 *   the compiled set; COMMAND_ACK each.
 * - HIL: DEBUG_FLOAT_ARRAY array_id 1 (`GL_SAMPLE`, data = y then r) answered by HIL_ACTUATOR_CONTROLS
 *   with the same time_usec, controls = u, flags bit 0 fault, bit 1 watchdog, bit 2 reset done, bits 8+k
 *   saturation of input k; array_id 2 resets the loop state, 3 is a period without a measurement.
 *   A committed gain set is staged into the loop right before the next step.
 *
 * Events (storage loaded, commit, refusal, ...) go to one hook, ::gl_mav_port_t::event, never to a
 * stream: the caller decides whether and how to log them.
 */
#ifndef GL_MAV_NODE_H
#define GL_MAV_NODE_H

#include <stddef.h>
#include <stdint.h>

#include "gainlink/gl_loop.h"
#include "gl_mav_params.h"
#include "gl_mav_store.h"

/** Where an answer goes. */
typedef enum gl_mav_dest {
    GL_MAV_TO_SENDER = 0, /**< To whoever sent the message being handled (a UDP peer); a serial link has one. */
    GL_MAV_TO_ALL = 1     /**< To every peer (heartbeats, streamed parameter lists). */
} gl_mav_dest_t;

/** What the node reports through ::gl_mav_port_t::event (`value`, `detail` per event). */
typedef enum gl_mav_event {
    GL_MAV_EV_STORE_LOADED = 0,   /**< Stored set loaded at start or on request: value = its crc32. */
    GL_MAV_EV_STORE_IGNORED = 1,  /**< Stored bytes refused: value = gl_mav_store_error_t, detail = line. */
    GL_MAV_EV_STORE_UNREADABLE = 2, /**< Storage read failed (I/O): nothing changed. */
    GL_MAV_EV_STORE_WRITTEN = 3,  /**< Committed set written: value = crc32, detail = bytes. */
    GL_MAV_EV_STORE_WRITE_FAILED = 4, /**< Writing failed (or no storage): nothing persisted. */
    GL_MAV_EV_COMMITTED = 5,      /**< A gain set was committed through GL_HASH: value = crc32. */
    GL_MAV_EV_COMMIT_REFUSED = 6, /**< A GL_HASH commit was refused: value = gl_status_t. */
    GL_MAV_EV_RESET = 7,          /**< Back to the compiled set (MAV_CMD_PREFLIGHT_STORAGE 2): value = crc32. */
    GL_MAV_EV_STAGE_FAILED = 8    /**< Staging the committed set into the loop failed: value = gl_status_t. */
} gl_mav_event_t;

/** Counters of the node and its link (all saturate at UINT32_MAX). */
typedef struct gl_mav_node_stats {
    uint32_t rx_bytes;        /**< Bytes fed to gl_mav_node_input(). */
    uint32_t frames;          /**< Frames accepted (CRC and framing good). */
    uint32_t frame_bytes;     /**< Bytes of the accepted frames. */
    uint32_t bad_frames;      /**< Frames rejected (bad CRC, unknown message, bad header or signature). */
    uint32_t samples;         /**< HIL samples stepped. */
    uint32_t refused_sets;    /**< PARAM_SETs refused (unknown, read-only, wrong type, bad value). */
    uint32_t tx_dropped;      /**< Messages the transport could not take. */
} gl_mav_node_stats_t;

/**
 * Persistent storage of the committed set: whole-blob read and atomic replace. A host supplies a file,
 * the QEMU image a semihosting file standing for flash, a board a flash sector (see firmware/README.md).
 */
typedef struct gl_mav_storage {
    void *ctx; /**< Passed back to both functions. */
    /** Replace the stored bytes atomically (an interrupted write keeps the old ones); 0 ok, -1 failed. */
    int (*write)(void *ctx, const uint8_t *data, size_t len);
    /** Read the stored bytes into `data` (at most `cap`); bytes read, 0 when nothing is stored, -1 on error. */
    long (*read)(void *ctx, uint8_t *data, size_t cap);
} gl_mav_storage_t;

/** What the node needs from its transport and platform. */
typedef struct gl_mav_port {
    void *ctx; /**< Passed back to every function. */
    /** Send one framed message; 0 when sent or queued, -1 when dropped. Required. */
    int (*send)(void *ctx, gl_mav_dest_t dest, const uint8_t *bytes, size_t len);
    /** Bytes the transport can take now without dropping; NULL: unlimited (e.g. UDP). */
    size_t (*room)(void *ctx);
    /** Monotonic time in microseconds. Required. */
    uint64_t (*now_us)(void *ctx);
    /** Event hook (NULL: none); must not block. */
    void (*event)(void *ctx, gl_mav_event_t event, int32_t value, uint32_t detail);
    /** Transport counters for SYS_STATUS (NULL: none): receive overruns and bytes dropped on transmit. */
    void (*link_counters)(void *ctx, uint32_t *rx_overruns, uint32_t *tx_dropped);
} gl_mav_port_t;

/** Node configuration. */
typedef struct gl_mav_node_config {
    uint8_t sysid;                     /**< Our system id (1..255). */
    uint8_t compid;                    /**< Our component id (e.g. MAV_COMP_ID_AUTOPILOT1 = 1). */
    uint8_t chan;                      /**< MAVLink channel (parse state and sequence numbers), < MAVLINK_COMM_NUM_BUFFERS. */
    uint32_t watchdog_periods;         /**< Idle periods before the loop's safe command. */
    gl_mav_port_t port;                /**< Transport and platform. */
    const gl_mav_storage_t *storage;   /**< Persistent storage, or NULL (then PREFLIGHT_STORAGE 0/1 fail). */
} gl_mav_node_config_t;

/** The node. Large (it holds the loop and the parameter table): give it static storage. */
typedef struct gl_mav_node {
    gl_mav_node_config_t cfg;          /**< Configuration. */
    gl_mav_params_t table;             /**< Parameters over the staged and committed sets. */
    gl_loop_t loop;                    /**< The control loop. */
    gl_mav_node_stats_t stats;         /**< Counters. */
    int dirty;                         /**< A committed set waits to be staged into the loop. */
    uint64_t next_beat_us;             /**< When the next HEARTBEAT is due. */
    int32_t list_next;                 /**< Next index of a PARAM_REQUEST_LIST being streamed, -1 none. */
    uint8_t store_buf[GL_MAV_STORE_MAX]; /**< Encode/decode buffer for storage. */
} gl_mav_node_t;

/**
 * @brief Initialise the node: parameters from the compiled set, then the stored set when there is one
 *        and it passes the checks (events report which), then the loop.
 * @param[out] node  Node.
 * @param[in]  cfg   Configuration (copied).
 * @return GL_OK, or the loop's refusal of the gain set (the node is then unusable).
 */
gl_status_t gl_mav_node_init(gl_mav_node_t *node, const gl_mav_node_config_t *cfg);

/**
 * @brief Parse bytes and handle every complete message (the entry point of a fuzz harness).
 * @param[in,out] node  Node.
 * @param[in]     bytes Received bytes (any split across calls is fine).
 * @param[in]     len   Their number.
 */
void gl_mav_node_input(gl_mav_node_t *node, const uint8_t *bytes, size_t len);

/**
 * @brief Periodic work: the 1 Hz heartbeat and the rest of a streamed parameter list.
 * @param[in,out] node Node.
 * @return Time (us, the port's clock) when it next has periodic work to do.
 */
uint64_t gl_mav_node_poll(gl_mav_node_t *node);

/** @brief Send a HEARTBEAT now (e.g. when a new peer appears). @param[in,out] node Node. */
void gl_mav_node_heartbeat(gl_mav_node_t *node);

/**
 * @brief Bytes fed to the node that were not part of an accepted frame (garbage, rejected or partial frames).
 * @param[in] node Node.
 * @return rx_bytes - frame_bytes.
 */
uint32_t gl_mav_node_garbage(const gl_mav_node_t *node);

#endif /* GL_MAV_NODE_H */
