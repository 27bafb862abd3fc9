/**
 * @file fuzz_mavlink_node.c
 * @brief libFuzzer harness: parse-and-dispatch of the MAVLink node (gl_mav_node_input), parameter server,
 *        commits, storage commands and signing.
 *
 * Byte 0 chooses the node: bit 0 a signing key 0x01 0x02 .. 0x20 (the seeds signed with it reach the
 * handlers) or none; bit 1 a trusted link; bit 2, without a key, a datagram link (no transmit limit: the host
 * app over UDP) instead of a serial one (a transmit ring of GL_FUZZ_TX_RING bytes that does not drain during
 * one input: the Cortex-M image's UART). A keyed node always gets the ring: the two links differ only in the
 * room check of a streamed parameter list, which the unkeyed datagram node covers, while a keyed node
 * streaming whole lists signs every answer (a SHA-256 each, ~60 per request for the pendulum). The rest is fed
 * to the node in two pieces split at byte 1 (a datagram boundary inside a frame must not matter). Storage
 * lives in RAM; answers are discarded. Oracles besides ASan/UBSan: the committed set always passes the
 * library's checks and is what the loop runs after a step; it changes only through an accepted commit, reset
 * or reload (counted); storage is written only through a persist, at most GL_MAV_PERSIST_BURST times (the
 * clock does not advance a minute); the counters add up (accepted frame bytes never exceed the bytes fed,
 * every answer the transport refused is counted as dropped).
 *
 * Speed: every input starts from a copy (gl_mav_node_copy()) of a node gl_mav_node_init() made once, rather
 * than initialising it again, and a serial link streams a parameter list only as its ring has room (as on the
 * image), not the whole list per request (each answer of a keyed node costs a SHA-256).
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "gl_mav_node.h"

/** Transmit ring of the serial link: the image's UART ring (ports/cortex-m/gl_uart.h, GL_UART_TX_SIZE). */
#define GL_FUZZ_TX_RING 2048u

#define MODE_KEYED 0x1u
#define MODE_TRUSTED 0x2u
#define MODE_DATAGRAM 0x4u

static gl_mav_node_t node;
static gl_mav_node_t pristine[4]; /* as gl_mav_node_init() left it, by (mode & 6) >> 1: link kinds */
static uint8_t flash[GL_MAV_STORE_MAX];
static size_t flash_len;
static uint32_t flash_writes;
static uint32_t changes; /* events that may change the committed set */
static uint32_t refused_sends;
static size_t tx_room;
static uint64_t clock_us;

static int port_send(void *ctx, gl_mav_dest_t dest, const uint8_t *bytes, size_t len)
{
    (void)ctx;
    (void)dest;
    if (bytes == NULL || len == 0u || len > MAVLINK_MAX_PACKET_LEN) {
        abort();
    }
    if (len > tx_room) {
        refused_sends++;
        return -1;
    }
    tx_room -= len;
    return 0;
}

static size_t port_room(void *ctx)
{
    (void)ctx;
    return tx_room;
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

/** Initialise the pristine nodes once (storage empty, as every input sees it). */
static void make_pristine(void)
{
    for (unsigned kind = 0; kind < 4u; ++kind) {
        const unsigned mode = kind << 1;
        const gl_mav_node_config_t cfg = {
            .sysid = 1, .compid = 1, .chan = 0, .watchdog_periods = 3,
            .port = {.ctx = NULL, .send = port_send, .room = (mode & MODE_DATAGRAM) ? NULL : port_room,
                     .now_us = port_now, .event = port_event, .link_counters = NULL, .store_key = NULL},
            .storage = &storage, .trusted_link = (mode & MODE_TRUSTED) != 0u,
        };
        if (gl_mav_node_init(&pristine[kind], &cfg) != GL_OK) {
            abort();
        }
    }
}

/** The node of `mode`, as gl_mav_node_init() makes it with empty storage. */
static void fresh_node(uint8_t mode)
{
    static int ready;
    if (!ready) {
        make_pristine();
        ready = 1;
    }
    flash_len = 0;
    flash_writes = 0;
    changes = 0;
    refused_sends = 0;
    clock_us = 1000000u;
    if (mode & MODE_KEYED) {
        mode &= (uint8_t)~MODE_DATAGRAM;
    }
    if (gl_mav_node_copy(&node, &pristine[(mode & (MODE_TRUSTED | MODE_DATAGRAM)) >> 1]) != GL_OK) {
        abort();
    }
    tx_room = (mode & MODE_DATAGRAM) ? SIZE_MAX : GL_FUZZ_TX_RING;
    if (mode & MODE_KEYED) {
        uint8_t key[GL_MAV_KEY_LEN];
        for (size_t i = 0; i < sizeof key; ++i) {
            key[i] = (uint8_t)(i + 1u);
        }
        gl_mav_node_set_key(&node, key, 0u);
    }
}

/** Unkeyed: one HIL sample must make the loop run the committed set (resynchronised first). */
static void check_step_runs_committed(void)
{
    mavlink_message_t msg;
    const mavlink_debug_float_array_t sample = {.time_usec = 1, .array_id = 1}; /* y = r = 0 */
    mavlink_msg_debug_float_array_encode_chan(200, 1, 1, &msg, &sample); /* channel 1: our own framing */
    uint8_t buf[MAVLINK_MAX_PACKET_LEN];
    uint16_t n = mavlink_msg_to_send_buffer(buf, &msg);
    gl_mav_node_resync(&node); /* a frame the input left half-parsed must not swallow the sample */
    gl_mav_node_input(&node, buf, n);
    if (gl_law_active_crc32(&node.law) != node.table.committed.crc32) {
        abort();
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 2u) {
        return 0;
    }
    fresh_node(data[0]);
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
    if (s->tx_dropped != refused_sends) {
        abort(); /* every answer the link refused is counted, nothing else */
    }
    if (gl_law_gains_check(&node.table.committed) != GL_OK) {
        abort(); /* whatever arrived, the committed set is a valid one */
    }
    if (node.table.committed.crc32 != crc_before && changes == 0u) {
        abort(); /* changed without an accepted commit, reset or reload */
    }
    if (flash_writes != s->persist_writes || flash_writes > GL_MAV_PERSIST_BURST) {
        abort();
    }
    if (!node.keyed) {
        tx_room = SIZE_MAX; /* room for the command, whatever the input left */
        check_step_runs_committed();
    }
    return 0;
}
