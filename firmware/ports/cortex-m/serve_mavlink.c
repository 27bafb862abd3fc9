/**
 * @file serve_mavlink.c
 * @brief The MAVLink node (apps/mavlink/gl_mav_node.h) on the console UART: the same protocol code as the
 *        host app, carried by the interrupt-driven rings of gl_uart.h. It runs the build's law (gl_law.h; a
 *        scheduled law's external sigma travels after the references in the HIL sample). Its ready line names the
 *        set in force: ` format=float32|q31|q15|scheduled-float32`, ` gains=persisted` (the one its flash held) or
 *        ` gains=artifact` (the compiled one; option `gains=artifact` starts on it whatever the flash holds) and its
 *        ` crc32=`, then ` signing=on|off`, the law and the wire format (` law=q31 wire=4`).
 *
 * A serial link has one peer, so every answer goes to the UART whatever its destination. The node's
 * events are not printed (the UART carries MAVLink); SYS_STATUS reports the counters. The UART is a
 * cable, so it is a trusted link for signing: an unsigned SETUP_SIGNING may set the first key (only the
 * first: with a key, a new one must come signed with it), which the node's store_key hook keeps in flash
 * (the semihosting file gl_key.bin) and the next start loads.
 *
 * The board has no wall clock, so its signing timestamp restarts from the newest one it kept: kept when a
 * key is set and whenever the node writes flash anyway (a persist), so a signed message recorded before
 * that point and replayed after a restart is refused as too old (more than a minute older), not accepted
 * by a node whose timestamp restarted from 0.
 */
#include <string.h>

#include "flash_semihost.h"
#include "gl_clock.h"
#include "gl_mav_node.h"
#include "gl_nvic.h"
#include "gl_uart.h"
#include "semihost.h"
#include "serve.h"

static gl_mav_node_t node;

static int uart_send(void *ctx, gl_mav_dest_t dest, const uint8_t *bytes, size_t len)
{
    (void)ctx;
    (void)dest;
    return gl_uart_write(bytes, len);
}

static size_t uart_room(void *ctx)
{
    (void)ctx;
    return gl_uart_tx_room();
}

static uint64_t clock_us(void *ctx)
{
    (void)ctx;
    return gl_clock_us();
}

static void uart_counters(void *ctx, uint32_t *rx_overruns, uint32_t *tx_dropped)
{
    (void)ctx;
    gl_uart_stats_t s;
    gl_uart_stats(&s);
    *rx_overruns = s.rx_overruns;
    *tx_dropped = s.tx_dropped;
}

static void node_event(void *ctx, gl_mav_event_t ev, int32_t value, uint32_t detail)
{
    (void)ctx;
    (void)value;
    (void)detail;
    if ((ev == GL_MAV_EV_KEY_SET || ev == GL_MAV_EV_STORE_WRITTEN) && node.keyed) {
        (void)gl_flash_store_timestamp(node.signing.timestamp);
    }
}

static void put_number(uint32_t v)
{
    char digits[10];
    size_t n = 0;
    do {
        digits[n++] = (char)('0' + v % 10u);
        v /= 10u;
    } while (v != 0u);
    while (n > 0u) {
        (void)gl_uart_write((const uint8_t *)&digits[--n], 1);
    }
}

int gl_serve_mavlink(int argc, char *const argv[])
{
    uint32_t sysid = 1, compid = 1;
    int from_artifact = 0; /* gains=artifact: start on the compiled set even when the flash holds one */
    for (int i = 0; i < argc; ++i) {
        const char *v;
        if (gl_serve_option(argv[i], "sysid", &v)) {
            if (gl_serve_number(v, 255u, &sysid) != 0 || sysid == 0u) {
                return gl_serve_refuse("sysid must be 1..255");
            }
        } else if (gl_serve_option(argv[i], "compid", &v)) {
            if (gl_serve_number(v, 255u, &compid) != 0) {
                return gl_serve_refuse("compid must be 0..255");
            }
        } else if (gl_serve_option(argv[i], "gains", &v)) {
            if (strcmp(v, "artifact") != 0) {
                return gl_serve_refuse("gains takes artifact");
            }
            from_artifact = 1;
        } else {
            return gl_serve_refuse("unknown mavlink option (sysid=N compid=N gains=artifact)");
        }
    }
    const gl_mav_node_config_t cfg = {
        .sysid = (uint8_t)sysid,
        .compid = (uint8_t)compid,
        .chan = 0,
        .watchdog_periods = GL_WATCHDOG_PERIODS_DEFAULT,
        .port = {.ctx = 0, .send = uart_send, .room = uart_room, .now_us = clock_us, .event = node_event,
                 .link_counters = uart_counters, .store_key = gl_flash_store_key},
        .storage = gl_flash_storage(),
        .trusted_link = 1,
        .ignore_stored = from_artifact,
    };
    if (gl_mav_node_init(&node, &cfg) != GL_OK) {
        (void)gl_serve_refuse("gain set rejected");
        return GL_EXIT_GAINS;
    }
    uint8_t key[GL_MAV_KEY_LEN];
    int keyed = gl_flash_load_key(key);
    if (keyed) {
        gl_mav_node_set_key(&node, key, gl_flash_load_timestamp()); /* then follows the newest it accepts */
    }
    static const char ready[] = "ready mavlink sysid=";
    (void)gl_uart_write((const uint8_t *)ready, sizeof ready - 1u);
    put_number(sysid);
    static const char format[] = " format=" GL_LAW_NAME;
    (void)gl_uart_write((const uint8_t *)format, sizeof format - 1u);
    static const char *const gains[2] = {" gains=artifact", " gains=persisted"};
    (void)gl_uart_write((const uint8_t *)gains[node.started_stored], strlen(gains[node.started_stored]));
    (void)gl_uart_write((const uint8_t *)" crc32=", 7);
    put_number(node.table.committed.crc32);
    (void)gl_uart_write((const uint8_t *)(keyed ? " signing=on" : " signing=off"), keyed ? 11u : 12u);
    static const char law[] = " law=" GL_LAW_NAME " wire=" GL_WIRE_VERSION_TEXT;
    (void)gl_uart_write((const uint8_t *)law, sizeof law - 1u);
    (void)gl_uart_write((const uint8_t *)"\n", 1);
    for (;;) {
        uint8_t buf[64];
        size_t n;
        while ((n = gl_uart_read(buf, sizeof buf)) > 0u) {
            gl_mav_node_input(&node, buf, n);
        }
        (void)gl_mav_node_poll(&node);
        gl_wait_for_interrupt(gl_uart_rx_ready);
    }
}
