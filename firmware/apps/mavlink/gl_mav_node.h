/**
 * @file gl_mav_node.h
 * @brief The MAVLink node of the control loop, independent of its transport: bytes in, bytes out.
 *
 * One node holds the build's law (::gl_law_t of gl_law.h), its parameter table and the MAVLink parse state of one
 * channel. Whatever carries the bytes (UDP on the host, a UART on the Cortex-M image, a fuzz harness)
 * feeds them to gl_mav_node_input() and gets the answers through ::gl_mav_port_t::send. It speaks:
 *
 * - HEARTBEAT at 1 Hz (gl_mav_node_poll()) and on demand (gl_mav_node_heartbeat(), e.g. to a new peer):
 *   MAV_TYPE_GENERIC, MAV_AUTOPILOT_GENERIC, custom_mode = the law it runs (GL_LAW_ID of gl_law.h: 0 float32, 31 q31,
 *   15 q15, 256 scheduled-float32).
 * - AUTOPILOT_VERSION on MAV_CMD_REQUEST_MESSAGE(148) or MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
 *   capabilities MAVLINK2 | PARAM_ENCODE_BYTEWISE, flight_custom_version = first 8 hex digits of the
 *   artifact's sha256, middleware_custom_version = "gainlink" (how an uploader tells a gainlink node, whose uid
 *   it may read as a gain set, from other autopilots, whose uid is a hardware id) and middleware_sw_version = the
 *   sample/command wire format (GL_WIRE_VERSION: 4), uid = CRC-32 of the committed gain set.
 * - SYS_STATUS on MAV_CMD_REQUEST_MESSAGE(1): the link's error counters (see gl_mav_node_stats_t).
 * - The parameter protocol over the gain set (naming in gl_mav_params.h): PARAM_REQUEST_LIST (streamed as
 *   the transport has room), PARAM_REQUEST_READ by id or index (PARAM_ERROR when unknown), PARAM_SET
 *   always answered with PARAM_VALUE (the value now held), then PARAM_ERROR when refused.
 * - MAV_CMD_PREFLIGHT_STORAGE param1 = 0 reload from storage, 1 write the committed set to it, 2 reset to
 *   the compiled set; COMMAND_ACK each.
 * - HIL: DEBUG_FLOAT_ARRAY array_id 1 (`GL_SAMPLE`, data = y then r, then a scheduled law's GL_LAW_E external
 *   scheduling signals) answered by HIL_ACTUATOR_CONTROLS with the same time_usec, controls = u and flags in wire
 *   format 2: bits 0-15 MAVLink's own (bit 0 its LOCKSTEP flag; none set), bits 16-31 the step's status flags
 *   (GL_FLAG_* of gl_flags.h, the one table: fault, watchdog, clipped, overflow, sigma held, clipped,
 *   rate-limited, reset), bits 32+k input k saturated; array_id 2 resets the law's state (answered with RESET), 3
 *   is a period without a measurement. A committed gain set is staged into the law right before the next step.
 *
 * Events (storage loaded, commit, refusal, ...) go to one hook, ::gl_mav_port_t::event, never to a
 * stream: the caller decides whether and how to log them.
 *
 * @par Signing (MAVLink 2 message signing, the mavgen library's own implementation)
 * With a key (gl_mav_node_set_key(): a key file at start, or SETUP_SIGNING), every message is checked by
 * mavlink_helpers.h (SHA-256 signature over the 32-byte secret key, link id, 48-bit timestamp in 10 us
 * units since 2015, replay protection per (sysid, compid, link id) stream) and every message the node sends
 * is signed. Only these stay open unsigned, because they change nothing and a ground station needs them to
 * find the node and show what it runs: HEARTBEAT, PARAM_REQUEST_LIST, PARAM_REQUEST_READ. Everything else —
 * PARAM_SET (staging, commits), COMMAND_LONG (persist, reload, reset, requests), SETUP_SIGNING and the HIL
 * samples, which drive the loop — is refused unless correctly signed, counted by reason (unsigned, bad
 * signature, replayed or too old, too many streams) and reported through the event hook; never applied.
 * Without a key the node accepts everything, as before. SETUP_SIGNING is accepted when it is signed with the
 * current key (a key change), or, with no key yet, on a link the configuration marks trusted (a cable:
 * the Cortex-M image's UART), never unsigned over a network link; an all-zero key turns signing off.
 *
 * @par Persist rate limit (flash wear)
 * MAV_CMD_PREFLIGHT_STORAGE 1 writes only when the committed set differs from the stored one (else
 * ACCEPTED without a write), and at most GL_MAV_PERSIST_BURST writes in a burst, then one per
 * GL_MAV_PERSIST_PERIOD_US; beyond that the answer is MAV_RESULT_TEMPORARILY_REJECTED (counted). A flash
 * sector takes about 10,000 erase cycles (STM32F4 datasheet): at the sustained limit of one write a minute a
 * client that persists non-stop takes a week to wear it out, a normal session persists a few times.
 */
#ifndef GL_MAV_NODE_H
#define GL_MAV_NODE_H

#include <stddef.h>
#include <stdint.h>

#include "common/mavlink.h"
#include "gainlink/gl_law.h"
#include "gl_mav_params.h"
#include "gl_mav_platform.h" /* gl_mav_storage_t, GL_MAV_KEY_LEN */
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
    GL_MAV_EV_STAGE_FAILED = 8,   /**< Staging the committed set into the loop failed: value = gl_status_t. */
    GL_MAV_EV_SIGNATURE_REFUSED = 9, /**< A message refused by signing: value = gl_mav_sig_refusal_t, detail = msgid. */
    GL_MAV_EV_PERSIST_LIMITED = 10,  /**< A persist refused by the rate limit: value = seconds to the next write. */
    GL_MAV_EV_KEY_SET = 11,          /**< Signing key set by SETUP_SIGNING: value 1 on, 0 off (all-zero key). */
    GL_MAV_EV_SETUP_REFUSED = 12     /**< SETUP_SIGNING refused (unsigned on an untrusted link): detail = sysid. */
} gl_mav_event_t;

/** Why signing refused a message (value of GL_MAV_EV_SIGNATURE_REFUSED). */
typedef enum gl_mav_sig_refusal {
    GL_MAV_SIG_UNSIGNED = 0,  /**< Not signed, and not one of the open messages. */
    GL_MAV_SIG_BAD = 1,       /**< Signature does not match (another key, or altered bytes). */
    GL_MAV_SIG_REPLAY = 2,    /**< Timestamp not newer than the stream's last one, or a new stream's too old. */
    GL_MAV_SIG_STREAMS = 3    /**< Too many signing streams (MAVLINK_MAX_SIGNING_STREAMS). */
} gl_mav_sig_refusal_t;

/** Persist rate limit: writes allowed in a burst ... */
#define GL_MAV_PERSIST_BURST 4u
/** ... then one more per this period (us). */
#define GL_MAV_PERSIST_PERIOD_US 60000000ull

/** Counters of the node and its link (all saturate at UINT32_MAX). */
typedef struct gl_mav_node_stats {
    uint32_t rx_bytes;        /**< Bytes fed to gl_mav_node_input(). */
    uint32_t frames;          /**< Frames accepted (CRC and framing good). */
    uint32_t frame_bytes;     /**< Bytes of the accepted frames. */
    uint32_t bad_frames;      /**< Frames rejected (bad CRC, unknown message, bad header or signature). */
    uint32_t samples;         /**< HIL samples stepped. */
    uint32_t refused_sets;    /**< PARAM_SETs refused (unknown, read-only, wrong type, bad value). */
    uint32_t tx_dropped;      /**< Messages the transport could not take. */
    uint32_t sig_unsigned;    /**< Of bad_frames: unsigned messages that need a signature (key set). */
    uint32_t sig_bad;         /**< Of bad_frames: bad signatures. */
    uint32_t sig_replay;      /**< Of bad_frames: replayed or too old timestamps. */
    uint32_t sig_streams;     /**< Of bad_frames: refused for want of a free signing stream. */
    uint32_t setup_refused;   /**< SETUP_SIGNING messages refused. */
    uint32_t commits;         /**< Gain sets committed. */
    uint32_t persist_writes;  /**< Committed set written to storage. */
    uint32_t persist_skipped; /**< Persist requests answered without a write (storage already holds the set). */
    uint32_t persist_limited; /**< Persist requests refused by the rate limit. */
} gl_mav_node_stats_t;

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
    /** Keep a key set by SETUP_SIGNING (NULL: it lasts until restart); 0 kept, -1 failed. */
    int (*store_key)(void *ctx, const uint8_t key[GL_MAV_KEY_LEN]);
} gl_mav_port_t;

/** Node configuration. */
typedef struct gl_mav_node_config {
    uint8_t sysid;                     /**< Our system id (1..255). */
    uint8_t compid;                    /**< Our component id (e.g. MAV_COMP_ID_AUTOPILOT1 = 1). */
    uint8_t chan;                      /**< MAVLink channel (parse state and sequence numbers), < MAVLINK_COMM_NUM_BUFFERS. */
    uint32_t watchdog_periods;         /**< Idle periods before the loop's safe command. */
    gl_mav_port_t port;                /**< Transport and platform. */
    const gl_mav_storage_t *storage;   /**< Persistent storage, or NULL (then PREFLIGHT_STORAGE 0/1 fail). */
    int trusted_link;                  /**< 1: the link is physically private (a cable): an unsigned SETUP_SIGNING
                                            may set the first key. 0 for network links. */
    int ignore_stored;                 /**< 1: start on the compiled set, not the stored one (storage is kept
                                            as it is until the next persist). 0: load it (the default). */
} gl_mav_node_config_t;

/** The node. Large (it holds the loop and the parameter table): give it static storage. */
typedef struct gl_mav_node {
    gl_mav_node_config_t cfg;          /**< Configuration. */
    gl_mav_params_t table;             /**< Parameters over the staged and committed sets. */
    gl_law_t law;                      /**< The law the node runs (gl_law.h), on the table's committed set. */
    gl_mav_node_stats_t stats;         /**< Counters. */
    int dirty;                         /**< A committed set waits to be staged into the loop. */
    uint64_t next_beat_us;             /**< When the next HEARTBEAT is due. */
    int32_t list_next;                 /**< Next index of a PARAM_REQUEST_LIST being streamed, -1 none. */
    uint8_t store_buf[GL_MAV_STORE_MAX]; /**< Encode/decode buffer for storage. */
    mavlink_signing_t signing;         /**< Key and outgoing timestamp (in use when `keyed`). */
    mavlink_signing_streams_t streams; /**< Last timestamp of each signing stream (replay protection). */
    int keyed;                         /**< 1 when a key is set: signatures are required and added. */
    uint32_t persist_tokens;           /**< Writes allowed now (rate limit). */
    uint64_t persist_refill_us;        /**< When the next token is due. */
    uint32_t stored_crc;               /**< crc32 of the set storage holds (valid when stored_known). */
    int stored_known;                  /**< 1 when storage is known to hold stored_crc. */
    int started_stored;                /**< 1 when the set in force at start came from storage, 0 the compiled
                                            set (what a start-up line must name). */
} gl_mav_node_t;

/**
 * @brief Initialise the node: parameters from the compiled set, then (unless `ignore_stored`) the stored set
 *        when there is one and it passes the checks (events report which; `started_stored` says which set is
 *        in force), then the loop.
 * @param[out] node  Node.
 * @param[in]  cfg   Configuration (copied).
 * @return GL_OK, or the loop's refusal of the gain set (the node is then unusable).
 */
gl_status_t gl_mav_node_init(gl_mav_node_t *node, const gl_mav_node_config_t *cfg);

/**
 * @brief Make `dst` a copy of `src` (a snapshot to restore, e.g. a fuzz harness's freshly initialised node).
 *
 * Parameters, law (running on its own state and its own table's set, see gl_law_copy()), counters, key and replay state
 * are copied; the MAVLink channel starts afresh as after gl_mav_node_init() (no frame in progress) and, with a
 * key, checks signatures against `dst`. `src` must not be in use on the same channel afterwards.
 * @param[out] dst Copy.
 * @param[in]  src Node made by gl_mav_node_init() (distinct from dst).
 * @return GL_OK, or GL_ERR_NULL.
 */
gl_status_t gl_mav_node_copy(gl_mav_node_t *dst, const gl_mav_node_t *src);

/**
 * @brief Set or clear the signing key.
 * @param[in,out] node       Node.
 * @param[in]     key        GL_MAV_KEY_LEN bytes, or NULL / all zero to turn signing off.
 * @param[in]     timestamp  Outgoing signing timestamp to start from (10 us units since 2015-01-01 UTC; the
 *                           host passes its clock, a board without a clock 0 — it then follows the newest
 *                           timestamp it accepts).
 */
void gl_mav_node_set_key(gl_mav_node_t *node, const uint8_t *key, uint64_t timestamp);

/**
 * @brief Parse bytes and handle every complete message (the entry point of a fuzz harness).
 * @param[in,out] node  Node.
 * @param[in]     bytes Received bytes (any split across calls is fine).
 * @param[in]     len   Their number.
 */
void gl_mav_node_input(gl_mav_node_t *node, const uint8_t *bytes, size_t len);

/**
 * @brief Drop a frame in progress: call at the end of each datagram of a datagram link (UDP).
 *
 * Over UDP a frame never spans datagrams; without this a datagram ending in a bogus frame header would make
 * the parser swallow the start of the next, well-formed datagram (a lost HIL sample). A byte stream (a UART)
 * must not call it between reads.
 * @param[in,out] node Node.
 */
void gl_mav_node_resync(gl_mav_node_t *node);

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
