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
 * Records are read up to `block` at a time. Each gl_sched_step() runs with interrupts masked, so its instruction
 * count (gainlink.firmware.cost) holds the step alone.
 */
#include <stdint.h>
#include <string.h>

#include "board.h"
#include "gainlink/gl_sched.h"
#include "gl_clock.h"
#include "gl_nvic.h"
#include "gl_uart.h"
#include "semihost.h"

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

static int run(void)
{
    gl_clock_init();
    gl_uart_init();
    uart_puts("gainlink " GL_NAME " ");
    uart_puts(gl_board_name);
    uart_puts(" sha256:" GL_ARTIFACT_SHA256 " scheduled\n");
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
