/**
 * @file main_sched.c
 * @brief Cortex-M image of a scheduled artifact: the scheduled loop (gl_sched.h) fed through semihosting files.
 *
 * Prints `gainlink NAME BOARD sha256:HEX scheduled` on the UART, opens `gl_in.bin` in the simulator's working
 * directory, writes `gl_out.bin`, and exits with the status of semihost.h. The stream (all little-endian):
 *
 * in:  header {uint32 magic 'GLS1', count, block, 0}, then `count` records
 *      {float y[GL_P], float r[GL_Q], float s[GL_EA]}
 * out: header {uint32 magic 'GLT1', count, n, m, p, q, npts, e}, then one record per input
 *      {int32 status, uint32 sat_mask, uint32 sigma_flags, float u[GL_M], float state[GL_SCHED_STATE_LEN]}
 *      (state: gl_sched_state() after the step; its sigma is the one the step used)
 *
 * Records are read up to `block` at a time (block 1 for a closed loop through FIFOs: gainlink.hil.loop.pil_scheduled).
 * Each gl_sched_step() runs with interrupts masked, so its instruction count (gainlink.firmware.cost) holds the step
 * alone.
 *
 * Built with GL_IMAGE_SERVE (sched-image.cmake: the boards with the RAM), the command line `serve mavlink ...` or
 * `serve slcan ...` (as main.c's) runs the MAVLink or the CAN node on the UART instead, on the scheduled law
 * (apps/mavlink/gl_mav_law.h, apps/can/gl_can_law.h pick it from gl_gains.h; ready line ` law=scheduled-float32`).
 */
#include <stdint.h>
#include <string.h>

#include "board.h"
#include "gainlink/gl_sched.h"
#include "gl_clock.h"
#include "gl_nvic.h"
#include "gl_uart.h"
#include "semihost.h"
#if GL_IMAGE_SERVE
#include "serve.h"
#endif

#define GL_SIN_MAGIC 0x31534C47u  /* "GLS1" */
#define GL_SOUT_MAGIC 0x31544C47u /* "GLT1" */
#ifndef GL_IMAGE_MAX_BLOCK
#define GL_IMAGE_MAX_BLOCK 64
#endif
#define GL_MAX_BLOCK ((uint32_t)GL_IMAGE_MAX_BLOCK)

typedef struct {
    float y[GL_P];
    float r[GL_Q];
    float s[GL_EA];
} in_record_t;

typedef struct {
    int32_t status;
    uint32_t sat_mask;
    uint32_t sigma_flags;
    float u[GL_M];
    float state[GL_SCHED_STATE_LEN];
} out_record_t;

_Static_assert(sizeof(in_record_t) == 4u * (GL_P + GL_Q + GL_EA), "in_record_t must be packed");
_Static_assert(sizeof(out_record_t) == 4u * (3u + GL_M + GL_SCHED_STATE_LEN), "out_record_t must be packed");

static gl_sched_t loop;
static in_record_t in_buf[GL_MAX_BLOCK];
static out_record_t out_buf[GL_MAX_BLOCK];

static void uart_puts(const char *s)
{
    (void)gl_uart_write((const uint8_t *)s, strlen(s));
}

/** One input record through the loop into its output record. */
static void replay_record(const in_record_t *in, out_record_t *o)
{
    const uint32_t primask = gl_irq_save();
    const gl_sched_status_t st = gl_sched_step(&loop, in->y, in->r, in->s, o->u);
    gl_irq_restore(primask);
    o->status = (int32_t)st;
    o->sat_mask = loop.sat_mask;
    o->sigma_flags = loop.sigma_flags;
    gl_sched_state(&loop, o->state);
}

/** The replay stream (see the file comment), `block` records at a time. */
static int replay_file(int32_t fin)
{
    uint32_t hdr[4];
    if (gl_sh_read_all(fin, hdr, sizeof hdr) != 0) {
        return GL_EXIT_IO;
    }
    if (hdr[0] != GL_SIN_MAGIC || hdr[2] == 0u) {
        return GL_EXIT_BAD_INPUT;
    }
    if (gl_sched_init(&loop, &gl_sched_default) != GL_SCHED_OK) {
        return GL_EXIT_GAINS;
    }
    int32_t fout = gl_sh_open("gl_out.bin", GL_SH_MODE_WB);
    if (fout < 0) {
        return GL_EXIT_IO;
    }
    const uint32_t count = hdr[1];
    const uint32_t block = hdr[2] < GL_MAX_BLOCK ? hdr[2] : GL_MAX_BLOCK;
    const uint32_t out_hdr[8] = {GL_SOUT_MAGIC, count, GL_N, GL_M, GL_P, GL_Q, GL_NPTS, GL_E};
    if (gl_sh_write_all(fout, out_hdr, sizeof out_hdr) != 0) {
        return GL_EXIT_IO;
    }
    for (uint32_t done = 0; done < count;) {
        const uint32_t chunk = (count - done) < block ? (count - done) : block;
        if (gl_sh_read_all(fin, in_buf, chunk * sizeof(in_record_t)) != 0) {
            return GL_EXIT_IO;
        }
        for (uint32_t k = 0; k < chunk; ++k) {
            replay_record(&in_buf[k], &out_buf[k]);
        }
        if (gl_sh_write_all(fout, out_buf, chunk * sizeof(out_record_t)) != 0) {
            return GL_EXIT_IO;
        }
        done += chunk;
    }
    gl_sh_close(fout);
    return GL_EXIT_OK;
}

/** `serve PROTOCOL OPTIONS...` after the program name: runs that node (returns only on a bad option); else -1. */
static int serve_if_asked(void)
{
    static char line[512];
    static char *words[16];
    int n = gl_sh_cmdline_words(line, sizeof line, words, 16);
    if (n < 2 || strcmp(words[1], "serve") != 0) {
        return -1;
    }
#if GL_IMAGE_SERVE
    if (n >= 3 && strcmp(words[2], "mavlink") == 0) {
        return gl_serve_mavlink(n - 3, &words[3]);
    }
    if (n >= 3 && strcmp(words[2], "slcan") == 0) {
        return gl_serve_slcan(n - 3, &words[3]);
    }
    return gl_serve_refuse("serve needs a protocol: mavlink or slcan");
#else
    uart_puts("error: this image carries no bus node (built without GL_IMAGE_SERVE)\n");
    return GL_EXIT_BAD_INPUT;
#endif
}

static int run(void)
{
    gl_clock_init();
    gl_uart_init();
    uart_puts("gainlink ");
    uart_puts(gl_artifact_name);
    uart_puts(" ");
    uart_puts(gl_board_name);
    uart_puts(" sha256:");
    uart_puts(gl_artifact_sha256);
    uart_puts(" scheduled\n");
    int served = serve_if_asked();
    if (served >= 0) {
        return served;
    }
    int32_t fin = gl_sh_open("gl_in.bin", GL_SH_MODE_RB);
    if (fin < 0) {
        return GL_EXIT_BAD_INPUT;
    }
    int rc = replay_file(fin);
    gl_sh_close(fin);
    return rc;
}

int main(void)
{
    int rc = run();
    (void)gl_uart_flush(1000u); /* what is still queued on the UART goes out before the simulator stops */
    return rc;
}
