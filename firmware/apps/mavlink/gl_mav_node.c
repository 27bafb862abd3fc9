/**
 * @file gl_mav_node.c
 * @brief The transport-independent MAVLink node (see gl_mav_node.h): parse, dispatch, answer.
 */
#include "gl_mav_node.h"

#include <string.h>

#include "common/mavlink.h"

#define HIL_ARRAY_SAMPLE 1
#define HIL_ARRAY_RESET 2
#define HIL_ARRAY_IDLE 3
#define HEARTBEAT_PERIOD_US 1000000u
/** Room kept free while streaming a parameter list, so a HIL answer always fits beside it. */
#define LIST_HEADROOM (2u * MAVLINK_MAX_PACKET_LEN)

_Static_assert(GL_P + GL_Q + GL_LAW_E <= 58, "DEBUG_FLOAT_ARRAY carries at most 58 values (y, r and s)");
_Static_assert(GL_M <= 16, "HIL_ACTUATOR_CONTROLS carries at most 16 commands");

static void inc(uint32_t *counter, uint32_t by)
{
    *counter = (*counter > UINT32_MAX - by) ? UINT32_MAX : *counter + by;
}

static uint16_t sat16(uint32_t v)
{
    return v > UINT16_MAX ? UINT16_MAX : (uint16_t)v;
}

/**
 * The messages that stay open without a signature when a key is set (see "Signing" in gl_mav_node.h):
 * they change nothing.
 */
static bool accept_unsigned(const mavlink_status_t *status, uint32_t msgid)
{
    (void)status;
    return msgid == MAVLINK_MSG_ID_HEARTBEAT || msgid == MAVLINK_MSG_ID_PARAM_REQUEST_LIST ||
           msgid == MAVLINK_MSG_ID_PARAM_REQUEST_READ;
}

static void event(const gl_mav_node_t *node, gl_mav_event_t ev, int32_t value, uint32_t detail)
{
    if (node->cfg.port.event != NULL) {
        node->cfg.port.event(node->cfg.port.ctx, ev, value, detail);
    }
}

static void emit(gl_mav_node_t *node, gl_mav_dest_t dest, const mavlink_message_t *msg)
{
    uint8_t buf[MAVLINK_MAX_PACKET_LEN];
    uint16_t len = mavlink_msg_to_send_buffer(buf, msg);
    if (node->cfg.port.send(node->cfg.port.ctx, dest, buf, len) != 0) {
        inc(&node->stats.tx_dropped, 1u);
    }
}

void gl_mav_node_heartbeat(gl_mav_node_t *node)
{
    mavlink_message_t msg;
    mavlink_msg_heartbeat_pack_chan(node->cfg.sysid, node->cfg.compid, node->cfg.chan, &msg, MAV_TYPE_GENERIC,
                                    MAV_AUTOPILOT_GENERIC, 0, GL_LAW_ID, MAV_STATE_ACTIVE);
    emit(node, GL_MAV_TO_ALL, &msg);
}

static void send_param(gl_mav_node_t *node, uint16_t index, gl_mav_dest_t dest)
{
    const gl_mav_params_t *t = &node->table;
    mavlink_message_t msg;
    mavlink_msg_param_value_pack_chan(node->cfg.sysid, node->cfg.compid, node->cfg.chan, &msg, t->param[index].id,
                                      gl_mav_params_value(t, index), t->param[index].type, t->count, index);
    emit(node, dest, &msg);
}

static void send_param_error(gl_mav_node_t *node, const mavlink_message_t *req, const char *id, int16_t index,
                             uint8_t error)
{
    char pid[GL_MAV_ID_LEN + 1];
    memcpy(pid, id, GL_MAV_ID_LEN);
    pid[GL_MAV_ID_LEN] = '\0';
    mavlink_message_t msg;
    mavlink_msg_param_error_pack_chan(node->cfg.sysid, node->cfg.compid, node->cfg.chan, &msg, req->sysid,
                                      req->compid, pid, index, error);
    emit(node, GL_MAV_TO_SENDER, &msg);
}

static void send_ack(gl_mav_node_t *node, const mavlink_message_t *req, uint16_t command, uint8_t result)
{
    mavlink_message_t msg;
    mavlink_msg_command_ack_pack_chan(node->cfg.sysid, node->cfg.compid, node->cfg.chan, &msg, command, result, 0, 0,
                                      req->sysid, req->compid);
    emit(node, GL_MAV_TO_SENDER, &msg);
}

static void send_version(gl_mav_node_t *node)
{
    uint8_t custom[8];
    memcpy(custom, gl_artifact_sha256, sizeof custom);
    const uint8_t mark[8] = {'g', 'a', 'i', 'n', 'l', 'i', 'n', 'k'}; /* a gainlink node: uid is the set it runs */
    const uint8_t none[8] = {0};
    const uint8_t uid2[18] = {0};
    mavlink_message_t msg;
    mavlink_msg_autopilot_version_pack_chan(
        node->cfg.sysid, node->cfg.compid, node->cfg.chan, &msg,
        MAV_PROTOCOL_CAPABILITY_MAVLINK2 | MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE, 0x00010000u, GL_WIRE_VERSION, 0,
        0, custom, mark, none, 0, 0, node->table.committed.crc32, uid2);
    emit(node, GL_MAV_TO_SENDER, &msg);
}

static void send_sys_status(gl_mav_node_t *node)
{
    uint32_t overruns = 0, link_dropped = 0;
    if (node->cfg.port.link_counters != NULL) {
        node->cfg.port.link_counters(node->cfg.port.ctx, &overruns, &link_dropped);
    }
    const gl_mav_node_stats_t *s = &node->stats;
    mavlink_message_t msg;
    mavlink_msg_sys_status_pack_chan(node->cfg.sysid, node->cfg.compid, node->cfg.chan, &msg, 0, 0, 0, 0, UINT16_MAX,
                                     -1, -1, 0, sat16(s->bad_frames), sat16(gl_mav_node_garbage(node)),
                                     sat16(overruns), sat16(link_dropped + s->tx_dropped), sat16(s->refused_sets), 0,
                                     0, 0);
    emit(node, GL_MAV_TO_SENDER, &msg);
}

static int for_us(const gl_mav_node_t *node, uint8_t target_system, uint8_t target_component)
{
    return (target_system == 0 || target_system == node->cfg.sysid) &&
           (target_component == 0 || target_component == node->cfg.compid);
}

static void handle_param_set(gl_mav_node_t *node, const mavlink_message_t *msg)
{
    mavlink_param_set_t set;
    mavlink_msg_param_set_decode(msg, &set);
    if (!for_us(node, set.target_system, set.target_component)) {
        return;
    }
    int32_t k = gl_mav_params_find(&node->table, set.param_id);
    if (k < 0) {
        inc(&node->stats.refused_sets, 1u);
        send_param_error(node, msg, set.param_id, -1, MAV_PARAM_ERROR_DOES_NOT_EXIST);
        return;
    }
    gl_mav_set_result_t r = gl_mav_params_set(&node->table, (uint16_t)k, set.param_value, set.param_type);
    int is_header = node->table.param[k].kind == GL_MAV_PARAM_HASH; /* the one header a set may change */
    if (r == GL_MAV_SET_OK && is_header) {
        node->dirty = 1;
        inc(&node->stats.commits, 1u);
        event(node, GL_MAV_EV_COMMITTED, (int32_t)node->table.committed.crc32, 0);
    }
    send_param(node, (uint16_t)k, GL_MAV_TO_ALL);
    if (r != GL_MAV_SET_OK) {
        inc(&node->stats.refused_sets, 1u);
        uint8_t err = r == GL_MAV_SET_READ_ONLY ? MAV_PARAM_ERROR_READ_ONLY : MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE;
        if (is_header && r == GL_MAV_SET_BAD_VALUE) {
            event(node, GL_MAV_EV_COMMIT_REFUSED, node->table.last_refusal, 0);
        }
        send_param_error(node, msg, set.param_id, (int16_t)k, err);
    }
}

static void handle_param_read(gl_mav_node_t *node, const mavlink_message_t *msg)
{
    mavlink_param_request_read_t rd;
    mavlink_msg_param_request_read_decode(msg, &rd);
    if (!for_us(node, rd.target_system, rd.target_component)) {
        return;
    }
    int32_t k = rd.param_index >= 0 ? rd.param_index : gl_mav_params_find(&node->table, rd.param_id);
    if (k < 0 || k >= (int32_t)node->table.count) {
        send_param_error(node, msg, rd.param_id, rd.param_index, MAV_PARAM_ERROR_DOES_NOT_EXIST);
        return;
    }
    send_param(node, (uint16_t)k, GL_MAV_TO_SENDER);
}

/** Send the rest of a PARAM_REQUEST_LIST while the transport has room for it. */
static void pump_list(gl_mav_node_t *node, gl_mav_dest_t dest)
{
    while (node->list_next >= 0 && node->list_next < (int32_t)node->table.count) {
        if (node->cfg.port.room != NULL && node->cfg.port.room(node->cfg.port.ctx) < LIST_HEADROOM) {
            return;
        }
        send_param(node, (uint16_t)node->list_next++, dest);
    }
    node->list_next = -1;
}

static void handle_param_list(gl_mav_node_t *node, const mavlink_message_t *msg)
{
    mavlink_param_request_list_t rq;
    mavlink_msg_param_request_list_decode(msg, &rq);
    if (for_us(node, rq.target_system, rq.target_component)) {
        node->list_next = 0;
        pump_list(node, GL_MAV_TO_SENDER);
    }
}

/** Load the stored set: 1 loaded, 0 nothing stored or no storage, -1 unreadable or refused (events say which). */
static int load_stored(gl_mav_node_t *node)
{
    const gl_mav_storage_t *st = node->cfg.storage;
    if (st == NULL) {
        return 0;
    }
    long n = st->read(st->ctx, node->store_buf, sizeof node->store_buf);
    if (n <= 0) {
        if (n < 0) {
            event(node, GL_MAV_EV_STORE_UNREADABLE, -1, 0);
        }
        return n < 0 ? -1 : 0;
    }
    gl_mav_store_result_t res = gl_mav_store_decode(&node->table, node->store_buf, (size_t)n);
    if (res.error != GL_MAV_STORE_OK) {
        event(node, GL_MAV_EV_STORE_IGNORED, (int32_t)res.error, res.error == GL_MAV_STORE_E_REFUSED ? (uint32_t)res.status : res.line);
        return -1;
    }
    node->stored_crc = node->table.committed.crc32;
    node->stored_known = 1;
    event(node, GL_MAV_EV_STORE_LOADED, (int32_t)node->table.committed.crc32, 0);
    return 1;
}

/** Take one write from the persist rate limit (GL_MAV_PERSIST_BURST, then one per GL_MAV_PERSIST_PERIOD_US). */
static int persist_token(gl_mav_node_t *node)
{
    uint64_t now = node->cfg.port.now_us(node->cfg.port.ctx);
    while (node->persist_tokens < GL_MAV_PERSIST_BURST && now >= node->persist_refill_us) {
        node->persist_tokens++;
        node->persist_refill_us += GL_MAV_PERSIST_PERIOD_US;
    }
    if (node->persist_tokens == GL_MAV_PERSIST_BURST) {
        node->persist_refill_us = now + GL_MAV_PERSIST_PERIOD_US; /* a full bucket does not bank time */
    }
    if (node->persist_tokens == 0u) {
        uint64_t wait_s = (node->persist_refill_us - now + 999999u) / 1000000u;
        inc(&node->stats.persist_limited, 1u);
        event(node, GL_MAV_EV_PERSIST_LIMITED, (int32_t)wait_s, 0);
        return 0;
    }
    node->persist_tokens--;
    return 1;
}

static uint8_t persist(gl_mav_node_t *node)
{
    const gl_mav_storage_t *st = node->cfg.storage;
    if (st != NULL && node->stored_known && node->stored_crc == node->table.committed.crc32) {
        inc(&node->stats.persist_skipped, 1u); /* storage already holds this set: no flash cycle */
        return MAV_RESULT_ACCEPTED;
    }
    if (st != NULL && !persist_token(node)) {
        return MAV_RESULT_TEMPORARILY_REJECTED;
    }
    size_t len = gl_mav_store_encode(&node->table, node->store_buf, sizeof node->store_buf);
    if (st == NULL || len == 0u || st->write(st->ctx, node->store_buf, len) != 0) {
        node->stored_known = 0;
        event(node, GL_MAV_EV_STORE_WRITE_FAILED, st == NULL ? 0 : -1, 0);
        return MAV_RESULT_FAILED;
    }
    inc(&node->stats.persist_writes, 1u);
    node->stored_crc = node->table.committed.crc32;
    node->stored_known = 1;
    event(node, GL_MAV_EV_STORE_WRITTEN, (int32_t)node->table.committed.crc32, (uint32_t)len);
    return MAV_RESULT_ACCEPTED;
}

static uint8_t storage_command(gl_mav_node_t *node, float action)
{
    if (action == 1.0f) {
        return persist(node);
    }
    if (action == 0.0f) {
        if (load_stored(node) != 1) {
            if (node->cfg.storage == NULL) {
                event(node, GL_MAV_EV_STORE_UNREADABLE, 0, 0);
            }
            return MAV_RESULT_FAILED;
        }
        node->dirty = 1;
        return MAV_RESULT_ACCEPTED;
    }
    if (action == 2.0f) {
        if (gl_mav_params_replace(&node->table, GL_MAV_DEFAULT_SET) != GL_OK) {
            return MAV_RESULT_FAILED;
        }
        node->dirty = 1;
        event(node, GL_MAV_EV_RESET, (int32_t)node->table.committed.crc32, 0);
        return MAV_RESULT_ACCEPTED;
    }
    return MAV_RESULT_UNSUPPORTED;
}

static void handle_request_message(gl_mav_node_t *node, const mavlink_message_t *msg, const mavlink_command_long_t *cmd)
{
    if (cmd->param1 == (float)MAVLINK_MSG_ID_AUTOPILOT_VERSION) {
        send_ack(node, msg, cmd->command, MAV_RESULT_ACCEPTED);
        send_version(node);
    } else if (cmd->param1 == (float)MAVLINK_MSG_ID_HEARTBEAT) {
        send_ack(node, msg, cmd->command, MAV_RESULT_ACCEPTED);
        gl_mav_node_heartbeat(node);
    } else if (cmd->param1 == (float)MAVLINK_MSG_ID_SYS_STATUS) {
        send_ack(node, msg, cmd->command, MAV_RESULT_ACCEPTED);
        send_sys_status(node);
    } else {
        send_ack(node, msg, cmd->command, MAV_RESULT_UNSUPPORTED);
    }
}

static void handle_command(gl_mav_node_t *node, const mavlink_message_t *msg)
{
    mavlink_command_long_t cmd;
    mavlink_msg_command_long_decode(msg, &cmd);
    if (!for_us(node, cmd.target_system, cmd.target_component)) {
        return;
    }
    switch (cmd.command) {
    case MAV_CMD_REQUEST_MESSAGE: handle_request_message(node, msg, &cmd); break;
    case MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
        send_ack(node, msg, cmd.command, MAV_RESULT_ACCEPTED);
        send_version(node);
        break;
    case MAV_CMD_PREFLIGHT_STORAGE: send_ack(node, msg, cmd.command, storage_command(node, cmd.param1)); break;
    default: send_ack(node, msg, cmd.command, MAV_RESULT_UNSUPPORTED); break;
    }
}

/** A committed set not yet in the law: staged now (the law's checks; in force from the next step). */
static void stage_if_dirty(gl_mav_node_t *node)
{
    if (node->dirty) {
        gl_status_t st = gl_law_stage(&node->law, &node->table.committed);
        if (st != GL_OK) {
            event(node, GL_MAV_EV_STAGE_FAILED, (int32_t)st, 0);
            return; /* stays dirty: tried again before the next step */
        }
        node->dirty = 0;
    }
}

/**
 * Reset the law's state. A committed set not yet running is staged first and the reset puts it in force with its
 * own initial state (gl_law_reset()): staging it after the reset would leave it pending behind it, and a second
 * commit before the next step would then be refused as busy while the parameters already reported it.
 */
static void reset_law(gl_mav_node_t *node, gl_law_out_t *out)
{
    stage_if_dirty(node);
    (void)gl_law_reset(&node->law, out);
}

/** The HIL_ACTUATOR_CONTROLS flags of an answer (wire format 4, as in 3): MAVLink's own bits 0-15 left alone (bit 0 is its
 *  LOCKSTEP flag), the law's status flags (the one table, gl_flags.h) at bits 16-31, the saturation mask at 32-47. */
static uint64_t hil_flags(const gl_law_out_t *out)
{
    return ((uint64_t)(out->flags & 0xFFFFu) << GL_FLAGS_MAVLINK_SHIFT) | ((uint64_t)out->sat << GL_SAT_MAVLINK_SHIFT);
}

static void handle_sample(gl_mav_node_t *node, const mavlink_message_t *msg)
{
    mavlink_debug_float_array_t in;
    mavlink_msg_debug_float_array_decode(msg, &in);
    gl_law_out_t out;
    if (in.array_id == HIL_ARRAY_SAMPLE) { /* data = y, r, then a scheduled law's external signals */
        stage_if_dirty(node);
        const float *r = GL_Q > 0 ? &in.data[GL_P] : NULL;
        const float *s = GL_LAW_E > 0 ? &in.data[GL_P + GL_Q] : NULL;
        (void)gl_law_step(&node->law, &in.data[0], r, s, &out);
        inc(&node->stats.samples, 1u);
    } else if (in.array_id == HIL_ARRAY_RESET) {
        reset_law(node, &out); /* the answer: the start command */
    } else if (in.array_id == HIL_ARRAY_IDLE) {
        (void)gl_law_idle(&node->law, &out);
    } else {
        return;
    }
    float controls[16] = {0};
    memcpy(controls, out.u, sizeof out.u);
    mavlink_message_t reply;
    mavlink_msg_hil_actuator_controls_pack_chan(node->cfg.sysid, node->cfg.compid, node->cfg.chan, &reply,
                                                in.time_usec, controls, 0, hil_flags(&out));
    emit(node, GL_MAV_TO_SENDER, &reply);
}

void gl_mav_node_set_key(gl_mav_node_t *node, const uint8_t *key, uint64_t timestamp)
{
    static const uint8_t zero[GL_MAV_KEY_LEN] = {0};
    mavlink_status_t *chan = mavlink_get_channel_status(node->cfg.chan);
    if (key == NULL || memcmp(key, zero, GL_MAV_KEY_LEN) == 0) {
        node->keyed = 0;
        chan->signing = NULL;
        chan->signing_streams = NULL;
        memset(&node->signing, 0, sizeof node->signing);
        return;
    }
    memcpy(node->signing.secret_key, key, GL_MAV_KEY_LEN);
    node->signing.flags = MAVLINK_SIGNING_FLAG_SIGN_OUTGOING;
    node->signing.link_id = node->cfg.chan;
    if (timestamp > node->signing.timestamp) {
        node->signing.timestamp = timestamp;
    }
    node->signing.accept_unsigned_callback = accept_unsigned;
    node->signing.last_status = MAVLINK_SIGNING_STATUS_NONE;
    memset(&node->streams, 0, sizeof node->streams); /* a new key starts new streams */
    chan->signing = &node->signing;
    chan->signing_streams = &node->streams;
    node->keyed = 1;
}

static void handle_setup_signing(gl_mav_node_t *node, const mavlink_message_t *msg)
{
    mavlink_setup_signing_t setup;
    mavlink_msg_setup_signing_decode(msg, &setup);
    if (!for_us(node, setup.target_system, setup.target_component)) {
        return;
    }
    /* Keyed: the parser only lets it through correctly signed with the current key. Not keyed: only a
     * trusted (physically private) link may set the first key. */
    if (!node->keyed && !node->cfg.trusted_link) {
        inc(&node->stats.setup_refused, 1u);
        event(node, GL_MAV_EV_SETUP_REFUSED, 0, msg->sysid);
        return;
    }
    gl_mav_node_set_key(node, setup.secret_key, setup.initial_timestamp);
    if (node->cfg.port.store_key != NULL && node->cfg.port.store_key(node->cfg.port.ctx, setup.secret_key) != 0) {
        event(node, GL_MAV_EV_STORE_WRITE_FAILED, -2, 0);
    }
    event(node, GL_MAV_EV_KEY_SET, node->keyed, 0);
}

static void dispatch(gl_mav_node_t *node, const mavlink_message_t *msg)
{
    switch (msg->msgid) {
    case MAVLINK_MSG_ID_SETUP_SIGNING: handle_setup_signing(node, msg); break;
    case MAVLINK_MSG_ID_DEBUG_FLOAT_ARRAY: handle_sample(node, msg); break;
    case MAVLINK_MSG_ID_PARAM_SET: handle_param_set(node, msg); break;
    case MAVLINK_MSG_ID_PARAM_REQUEST_READ: handle_param_read(node, msg); break;
    case MAVLINK_MSG_ID_PARAM_REQUEST_LIST: handle_param_list(node, msg); break;
    case MAVLINK_MSG_ID_COMMAND_LONG: handle_command(node, msg); break;
    default: break;
    }
}

static uint32_t frame_size(const mavlink_message_t *msg)
{
    if (msg->magic == MAVLINK_STX_MAVLINK1) {
        return MAVLINK_CORE_HEADER_MAVLINK1_LEN + 1u + MAVLINK_NUM_CHECKSUM_BYTES + msg->len;
    }
    uint32_t signature = (msg->incompat_flags & MAVLINK_IFLAG_SIGNED) ? MAVLINK_SIGNATURE_BLOCK_LEN : 0u;
    return MAVLINK_NUM_NON_PAYLOAD_BYTES + msg->len + signature;
}

/** Count a frame the signing check refused, by reason, and report it. */
static void signature_refused(gl_mav_node_t *node, const mavlink_message_t *msg)
{
    gl_mav_sig_refusal_t why = GL_MAV_SIG_UNSIGNED;
    uint32_t *counter = &node->stats.sig_unsigned;
    if (msg->incompat_flags & MAVLINK_IFLAG_SIGNED) {
        switch (node->signing.last_status) {
        case MAVLINK_SIGNING_STATUS_REPLAY:
        case MAVLINK_SIGNING_STATUS_OLD_TIMESTAMP: why = GL_MAV_SIG_REPLAY; counter = &node->stats.sig_replay; break;
        case MAVLINK_SIGNING_STATUS_TOO_MANY_STREAMS:
        case MAVLINK_SIGNING_STATUS_NO_STREAMS: why = GL_MAV_SIG_STREAMS; counter = &node->stats.sig_streams; break;
        default: why = GL_MAV_SIG_BAD; counter = &node->stats.sig_bad; break;
        }
    }
    inc(counter, 1u);
    event(node, GL_MAV_EV_SIGNATURE_REFUSED, (int32_t)why, msg->msgid);
}

void gl_mav_node_input(gl_mav_node_t *node, const uint8_t *bytes, size_t len)
{
    for (size_t i = 0; i < len; ++i) {
        mavlink_message_t msg;
        mavlink_status_t st;
        inc(&node->stats.rx_bytes, 1u);
        /* mavlink_frame_char (not _parse_char) tells a bad CRC from a refused signature; header errors at this
         * byte come back in st.packet_rx_drop_count. */
        uint8_t r = mavlink_frame_char(node->cfg.chan, bytes[i], &msg, &st);
        inc(&node->stats.bad_frames, (uint32_t)st.packet_rx_drop_count);
        if (r == MAVLINK_FRAMING_OK) {
            inc(&node->stats.frames, 1u);
            inc(&node->stats.frame_bytes, frame_size(&msg));
            dispatch(node, &msg);
        } else if (r == MAVLINK_FRAMING_BAD_CRC) {
            inc(&node->stats.bad_frames, 1u);
        } else if (r == MAVLINK_FRAMING_BAD_SIGNATURE) {
            inc(&node->stats.bad_frames, 1u);
            signature_refused(node, &msg);
        }
    }
}

void gl_mav_node_resync(gl_mav_node_t *node)
{
    mavlink_reset_channel_status(node->cfg.chan);
}

uint64_t gl_mav_node_poll(gl_mav_node_t *node)
{
    uint64_t now = node->cfg.port.now_us(node->cfg.port.ctx);
    if (now >= node->next_beat_us) {
        gl_mav_node_heartbeat(node);
        node->next_beat_us = now + HEARTBEAT_PERIOD_US;
    }
    pump_list(node, GL_MAV_TO_ALL);
    return node->next_beat_us;
}

uint32_t gl_mav_node_garbage(const gl_mav_node_t *node)
{
    return node->stats.rx_bytes > node->stats.frame_bytes ? node->stats.rx_bytes - node->stats.frame_bytes : 0u;
}

gl_status_t gl_mav_node_init(gl_mav_node_t *node, const gl_mav_node_config_t *cfg)
{
    memset(node, 0, sizeof *node);
    node->cfg = *cfg;
    node->list_next = -1;
    node->persist_tokens = GL_MAV_PERSIST_BURST;
    memset(mavlink_get_channel_status(cfg->chan), 0, sizeof(mavlink_status_t));
    gl_mav_params_init(&node->table, GL_MAV_DEFAULT_SET);
    node->started_stored = cfg->ignore_stored ? 0 : load_stored(node) == 1;
    /* the law starts on the compiled set, then runs the table's committed set (the compiled one or the stored one)
     * from its own initial state */
    gl_status_t st = gl_law_init(&node->law, cfg->watchdog_periods);
    if (st == GL_OK) {
        st = gl_law_stage(&node->law, &node->table.committed);
    }
    if (st == GL_OK) {
        gl_law_out_t out;
        st = gl_law_reset(&node->law, &out);
    }
    return st;
}

gl_status_t gl_mav_node_copy(gl_mav_node_t *dst, const gl_mav_node_t *src)
{
    if (dst == NULL || src == NULL || dst == src) {
        return GL_ERR_NULL;
    }
    memcpy(dst, src, sizeof *dst);
    gl_status_t st = gl_law_copy(&dst->law, &src->law, &src->table.committed, &dst->table.committed);
    if (st != GL_OK) {
        return st;
    }
    /* The channel state lives in mavgen's per-file statics: only this file's are the node's. */
    mavlink_status_t *chan = mavlink_get_channel_status(dst->cfg.chan);
    memset(chan, 0, sizeof *chan);
    if (dst->keyed) {
        chan->signing = &dst->signing;
        chan->signing_streams = &dst->streams;
    }
    return GL_OK;
}
