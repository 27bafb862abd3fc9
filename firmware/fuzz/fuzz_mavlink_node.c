/**
 * @file fuzz_mavlink_node.c
 * @brief libFuzzer harness: parse-and-dispatch of the MAVLink node (gl_mav_node_input), parameter server,
 *        commits, storage commands and signing.
 *
 * Byte 0 bit 0 chooses a node with the signing key 0x01 0x02 .. 0x20 (the seeds signed with it reach the
 * handlers) or without one; byte 0 bit 1 marks the link trusted. The rest is fed to the node in two pieces
 * split at byte 1 (a datagram boundary inside a frame must not matter). Storage lives in RAM; answers are
 * discarded. Oracles besides ASan/UBSan: the committed set always passes the library's checks and is what
 * the loop runs after a step; it changes only through an accepted commit, reset or reload (counted); storage is
 * written only through a persist, at most GL_MAV_PERSIST_BURST times (the clock does not advance a minute);
 * the counters add up (accepted frame bytes never exceed the bytes fed).
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "gl_mav_node.h"

static gl_mav_node_t node;
static uint8_t flash[GL_MAV_STORE_MAX];
static size_t flash_len;
static uint32_t flash_writes;
static uint32_t changes; /* events that may change the committed set */
static uint64_t clock_us;

static int port_send(void *ctx, gl_mav_dest_t dest, const uint8_t *bytes, size_t len)
{
    (void)ctx;
    (void)dest;
    return (bytes == NULL || len == 0u || len > MAVLINK_MAX_PACKET_LEN) ? (abort(), -1) : 0;
}

static uint64_t port_now(void *ctx)
{
    (void)ctx;
    return clock_us += 10u;
}

static void port_event(void *ctx, gl_mav_event_t ev, int32_t value, uint32_t detail)
{
    (void)ctx;
    (void)value;
    (void)detail;
    if (ev == GL_MAV_EV_COMMITTED || ev == GL_MAV_EV_RESET || ev == GL_MAV_EV_STORE_LOADED) {
        changes++;
    }
}

static int flash_write(void *ctx, const uint8_t *data, size_t len)
{
    (void)ctx;
    if (len > sizeof flash) {
        abort();
    }
    memcpy(flash, data, len);
    flash_len = len;
    flash_writes++;
    return 0;
}

static long flash_read(void *ctx, uint8_t *data, size_t cap)
{
    (void)ctx;
    size_t n = flash_len < cap ? flash_len : cap;
    memcpy(data, flash, n);
    return (long)n;
}

static const gl_mav_storage_t storage = {.ctx = NULL, .write = flash_write, .read = flash_read};

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 2u) {
        return 0;
    }
    flash_len = 0;
    flash_writes = 0;
    changes = 0;
    clock_us = 1000000u;
    const gl_mav_node_config_t cfg = {
        .sysid = 1, .compid = 1, .chan = 0, .watchdog_periods = 3,
        .port = {.ctx = NULL, .send = port_send, .room = NULL, .now_us = port_now, .event = port_event,
                 .link_counters = NULL, .store_key = NULL},
        .storage = &storage, .trusted_link = (data[0] >> 1) & 1,
    };
    if (gl_mav_node_init(&node, &cfg) != GL_OK) {
        abort();
    }
    if (data[0] & 1u) {
        uint8_t key[GL_MAV_KEY_LEN];
        for (size_t i = 0; i < sizeof key; ++i) {
            key[i] = (uint8_t)(i + 1u);
        }
        gl_mav_node_set_key(&node, key, 0u);
    }
    const uint32_t crc_before = node.table.committed.crc32;
    const uint8_t *bytes = &data[2];
    const size_t len = size - 2u;
    const size_t cut = data[1] < len ? data[1] : len;
    gl_mav_node_input(&node, bytes, cut);
    gl_mav_node_input(&node, bytes + cut, len - cut);
    (void)gl_mav_node_poll(&node);

    const gl_mav_node_stats_t *s = &node.stats;
    if (s->frame_bytes > s->rx_bytes || s->rx_bytes != len) {
        abort();
    }
    if (gl_gains_check(&node.table.committed) != GL_OK) {
        abort(); /* whatever arrived, the committed set is a valid one */
    }
    if (node.table.committed.crc32 != crc_before && changes == 0u) {
        abort(); /* changed without an accepted commit, reset or reload */
    }
    if (flash_writes != s->persist_writes || flash_writes > GL_MAV_PERSIST_BURST) {
        abort();
    }
    if (!node.keyed) {
        mavlink_message_t msg;
        const mavlink_debug_float_array_t sample = {.time_usec = 1, .array_id = 1}; /* y = r = 0 */
        mavlink_msg_debug_float_array_encode_chan(200, 1, 1, &msg, &sample); /* channel 1: our own framing */
        uint8_t buf[MAVLINK_MAX_PACKET_LEN];
        uint16_t n = mavlink_msg_to_send_buffer(buf, &msg);
        gl_mav_node_resync(&node); /* a frame the input left half-parsed must not swallow the sample */
        gl_mav_node_input(&node, buf, n); /* one step: the loop now runs the committed set */
        if (gl_loop_active_crc32(&node.loop) != node.table.committed.crc32) {
            abort();
        }
    }
    return 0;
}
