/**
 * @file main_fixed.c
 * @brief Cortex-M image of the fixed-point loop (gl_fixed.h): replay and PIL through semihosting files.
 *
 * Prints `gainlink NAME BOARD sha256:HEX q31|q15` on the UART, then reads `gl_in.bin` in the simulator's working
 * directory (a file or a FIFO) and writes `gl_out.bin`, through the float image's stream code (gl_stream.c), so
 * replay and PIL (gainlink.hil.loop.pil, one record per FIFO round trip) drive both images alike. in: the float
 * image's stream (main.c: header {'GLI1', count, block, watchdog_periods}, records {uint32 tag, float y[GL_FX_P],
 * float r[GL_FX_QA]}; every record is a step, the watchdog word is ignored); out: header {uint32 'GLF1', count, n,
 * m, p, q, 0, 0}, then one gl_fixed_record_t per step (gl_fixed_record.h).
 * Without gl_in.bin: one step with y = 0, r = 0 and exit 0. Each gl_fixed_step() runs with interrupts masked,
 * so its instruction count (gainlink.firmware.cost) holds the step alone.
 */
#include <stdint.h>
#include <string.h>

#include "board.h"
#include "gl_clock.h"
#include "gl_fixed_record.h"
#include "gl_nvic.h"
#include "gl_stream.h"
#include "gl_uart.h"
#include "semihost.h"

#define GL_IN_MAGIC 0x31494C47u  /* "GLI1" */
#define GL_OUT_MAGIC 0x31464C47u /* "GLF1" */
#ifndef GL_IMAGE_MAX_BLOCK
#define GL_IMAGE_MAX_BLOCK 64
#endif
#define GL_MAX_BLOCK ((uint32_t)GL_IMAGE_MAX_BLOCK)
#if GL_NUMERIC_Q31
#define GL_FX_NUMERIC_NAME "q31"
#else
#define GL_FX_NUMERIC_NAME "q15"
#endif

typedef struct {
    uint32_t tag;
    float y[GL_FX_P];
    float r[GL_FX_QA];
} in_record_t;

_Static_assert(sizeof(in_record_t) == 4u * (1u + GL_FX_P + GL_FX_QA), "in_record_t must be packed");

static gl_fixed_loop_t loop;
static in_record_t in_buf[GL_MAX_BLOCK];
static gl_fixed_record_t out_buf[GL_MAX_BLOCK];

static void uart_puts(const char *s)
{
    (void)gl_uart_write((const uint8_t *)s, strlen(s));
}

/** One input record (every record is a step) through the integer law into its output record. */
static void replay_record(const void *in_record, void *out_record)
{
    const in_record_t *in = (const in_record_t *)in_record;
    float u[GL_FX_M];
    const uint32_t primask = gl_irq_save();
    (void)gl_fixed_step(&loop, in->y, in->r, u);
    gl_irq_restore(primask);
    gl_fixed_record(&loop, u, (gl_fixed_record_t *)out_record);
}

/** The stream's start (the loop was started by run(); no watchdog: header word 3 is ignored). */
static int replay_begin(const uint32_t in_hdr[4], uint32_t out_hdr[8])
{
    (void)in_hdr;
    const uint32_t words[6] = {GL_FX_N, GL_FX_M, GL_FX_P, GL_FX_Q, 0u, 0u};
    memcpy(&out_hdr[2], words, sizeof words);
    return GL_EXIT_OK;
}

static const gl_stream_t replay_stream = {
    .in_magic = GL_IN_MAGIC,
    .out_magic = GL_OUT_MAGIC,
    .in_size = sizeof(in_record_t),
    .out_size = sizeof(gl_fixed_record_t),
    .max_block = GL_MAX_BLOCK,
    .in_buf = in_buf,
    .out_buf = out_buf,
    .begin = replay_begin,
    .record = replay_record,
};

static int run(void)
{
    gl_clock_init();
    gl_uart_init();
    uart_puts("gainlink " GL_FX_NAME " ");
    uart_puts(gl_board_name);
    uart_puts(" sha256:" GL_FX_ARTIFACT_SHA256 " " GL_FX_NUMERIC_NAME "\n");
    (void)gl_fixed_init(&loop, &gl_fixed_gains_default);
    int32_t fin = gl_sh_open("gl_in.bin", GL_SH_MODE_RB);
    if (fin < 0) {
        in_record_t zero;
        memset(&zero, 0, sizeof zero);
        replay_record(&zero, &out_buf[0]);
        return GL_EXIT_OK;
    }
    int rc = gl_stream_replay(fin, &replay_stream);
    gl_sh_close(fin);
    return rc;
}

int main(void)
{
    int rc = run();
    (void)gl_uart_flush(1000u);
    return rc;
}
