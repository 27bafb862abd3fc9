/**
 * @file fuzz_slcan.c
 * @brief libFuzzer harness: the slcan (Lawicel) adapter's line parser (gl_slcan_input), bytes in, frames out.
 *
 * The input is fed in two pieces split at byte 0 (a serial read boundary inside a line must not matter).
 * Oracles besides ASan/UBSan: every delivered frame is a classic standard data frame (id <= 0x7FF, at most 8
 * bytes, not FD) and is counted; every answer is a line the protocol knows, ending in CR or BEL; sending a
 * delivered frame back out through an open adapter and feeding that line to a second open adapter delivers
 * the same frame (the adapter reads what it writes).
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "gl_slcan.h"

static uint32_t delivered;
static gl_can_frame_t last;
static int have_last;

static int check_answer(void *ctx, const uint8_t *bytes, size_t len)
{
    (void)ctx;
    if (len == 0u || len > 64u || (bytes[len - 1u] != '\r' && bytes[len - 1u] != '\a')) {
        abort();
    }
    return 0;
}

static void take_frame(void *ctx, const gl_can_frame_t *frame)
{
    (void)ctx;
    if (frame->id > 0x7FFu || frame->len > 8u || frame->fd) {
        abort();
    }
    delivered++;
    last = *frame;
    have_last = 1;
}

static uint8_t line_out[64];
static size_t line_out_len;

static int keep_line(void *ctx, const uint8_t *bytes, size_t len)
{
    (void)ctx;
    if (len <= sizeof line_out) {
        memcpy(line_out, bytes, len);
        line_out_len = len;
    }
    return 0;
}

static gl_can_frame_t echoed;
static int have_echoed;

static void take_echo(void *ctx, const gl_can_frame_t *frame)
{
    (void)ctx;
    echoed = *frame;
    have_echoed = 1;
}

static int discard(void *ctx, const uint8_t *bytes, size_t len)
{
    (void)ctx;
    (void)bytes;
    (void)len;
    return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1u) {
        return 0;
    }
    delivered = 0;
    have_last = 0;
    static gl_slcan_t s;
    const gl_slcan_port_t port = {.ctx = NULL, .write = check_answer, .frame = take_frame, .overruns = NULL};
    gl_slcan_init(&s, &port);
    const uint8_t *bytes = &data[1];
    const size_t len = size - 1u;
    const size_t cut = data[0] < len ? data[0] : len;
    gl_slcan_input(&s, bytes, cut);
    gl_slcan_input(&s, bytes + cut, len - cut);
    if (s.stats.frames_in != delivered) {
        abort();
    }
    if (!have_last) {
        return 0;
    }
    static gl_slcan_t tx, rx;
    const gl_slcan_port_t tx_port = {.ctx = NULL, .write = keep_line, .frame = take_frame, .overruns = NULL};
    const gl_slcan_port_t rx_port = {.ctx = NULL, .write = discard, .frame = take_echo, .overruns = NULL};
    gl_slcan_init(&tx, &tx_port);
    gl_slcan_init(&rx, &rx_port);
    static const uint8_t open_cmd[] = {'O', '\r'};
    gl_slcan_input(&tx, open_cmd, sizeof open_cmd);
    gl_slcan_input(&rx, open_cmd, sizeof open_cmd);
    line_out_len = 0;
    have_echoed = 0;
    if (gl_slcan_send(&tx, &last) != 0 || line_out_len == 0u) {
        abort(); /* an open adapter sends any frame it delivered */
    }
    gl_slcan_input(&rx, line_out, line_out_len);
    if (!have_echoed || echoed.id != last.id || echoed.len != last.len || memcmp(echoed.data, last.data, last.len) != 0) {
        abort();
    }
    return 0;
}
