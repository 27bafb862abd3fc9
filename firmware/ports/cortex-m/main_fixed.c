/**
 * @file main_fixed.c
 * @brief Cortex-M image of the fixed-point loop (gl_fixed.h): replay through semihosting files.
 *
 * Prints `gainlink NAME BOARD sha256:HEX q31|q15` on the UART, then reads `gl_in.bin` in the simulator's working
 * directory (the float image's input stream, main.c: header {'GLI1', count, block, watchdog_periods}, records
 * {uint32 tag, float y[GL_FX_P], float r[GL_FX_QA]}; every record is a step) and writes `gl_out.bin`:
 * header {uint32 'GLF1', count, n, m, p, q, 0, 0}, then one gl_fixed_record_t per step (gl_fixed_record.h).
 * Without gl_in.bin: one step with y = 0, r = 0 and exit 0. Each gl_fixed_step() runs with interrupts masked,
 * so its instruction count (gainlink.firmware.cost) holds the step alone.
 */
#include <stdint.h>
#include <string.h>

#include "board.h"
#include "gl_clock.h"
#include "gl_fixed_record.h"
#include "gl_nvic.h"
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

static void replay_record(const in_record_t *in, gl_fixed_record_t *o)
{
    float u[GL_FX_M];
    const uint32_t primask = gl_irq_save();
    (void)gl_fixed_step(&loop, in->y, in->r, u);
    gl_irq_restore(primask);
    gl_fixed_record(&loop, u, o);
}

static int replay_file(int32_t fin)
{
    uint32_t hdr[4];
    if (gl_sh_read_all(fin, hdr, sizeof hdr) != 0) {
        return GL_EXIT_IO;
    }
    if (hdr[0] != GL_IN_MAGIC || hdr[2] == 0u) {
        return GL_EXIT_BAD_INPUT;
    }
    int32_t fout = gl_sh_open("gl_out.bin", GL_SH_MODE_WB);
    if (fout < 0) {
        return GL_EXIT_IO;
    }
    const uint32_t count = hdr[1];
    const uint32_t block = hdr[2] < GL_MAX_BLOCK ? hdr[2] : GL_MAX_BLOCK;
    const uint32_t out_hdr[8] = {GL_OUT_MAGIC, count, GL_FX_N, GL_FX_M, GL_FX_P, GL_FX_Q, 0u, 0u};
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
        if (gl_sh_write_all(fout, out_buf, chunk * sizeof(gl_fixed_record_t)) != 0) {
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
    int rc = replay_file(fin);
    gl_sh_close(fin);
    return rc;
}

int main(void)
{
    int rc = run();
    (void)gl_uart_flush(1000u);
    return rc;
}
