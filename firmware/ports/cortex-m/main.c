/**
 * @file main.c
 * @brief Cortex-M image: the build's law (gl_law.h) as a bus node on its UART (MAVLink or slcan), or fed through
 *        semihosting files (replay and PIL), or a UART smoke test. One main for every law.
 *
 * Starts the millisecond clock and the interrupt-driven UART (gl_uart.h) and prints
 * `gainlink NAME BOARD sha256:HEX law=LAW variant=VARIANT wire=N` on it. Then, by the simulator's command line
 * (semihosting SYS_GET_CMDLINE; QEMU: `-semihosting-config enable=on,target=native,arg=gainlink,arg=serve,arg=mavlink`):
 * - `serve mavlink [sysid=N] [compid=N] [gains=artifact]`: the MAVLink node on the UART (serve.h), parameters persisted
 *   in the semihosting file gl_flash.txt (flash_semihost.h); runs until the simulator is stopped;
 * - `serve slcan [base=ID] [encoding=float32|int16 meas=... cmd=...]`: the CAN node behind slcan (serve.h);
 *   (images built with GL_IMAGE_SERVE only; the others answer `serve` with exit status GL_EXIT_BAD_INPUT;
 *   an image without the MAVLink node, GL_IMAGE_SERVE_MAVLINK off, refuses `serve mavlink`: the micro:bit's);
 * - anything else: opens `gl_in.bin` (a file or a FIFO) in the simulator's working directory. Without it,
 *   the UART smoke test runs: one step with y = 0.5, r = 0, s = 0, printed as `step STATUS u=0xBITS ...`, exit 0.
 *   With it, `gl_out.bin` is opened for writing and the stream is (gl_stream.h; records generated from the law's
 *   one description, GL_LAW_RECORD_HEADER of gl_law.h and gainlink.shipping.records):
 *
 * in:  header {uint32 magic 'GLI2', count, block, watchdog_periods}, then `count` gl_law_sample_t
 *      {uint32 tag (0 step, 1 idle, 2 stage, 3 reset), float y[GL_P], float r[GL_QA], float s[GL_LAW_EA]}
 *      A stage record reads a whole gl_law_gains_t from `gl_stageK.bin` (K = 0, 1, ... per stage record) and
 *      hands it to gl_law_stage(); its output record carries that status and the held command.
 * out: header {uint32 magic 'GLO2', count, GL_LAW_ID, n, m, p, q, e}, then one gl_law_record_t per input.
 *
 * Records are read up to `block` at a time (use block 1 for a closed loop through FIFOs); the image reads
 * fewer when its buffers are smaller (GL_IMAGE_MAX_BLOCK). All little-endian.
 *
 * Each step of the replay runs with interrupts masked: the step's instruction count (gainlink.firmware.cost, from
 * the call of the law's own step function, GL_LAW_STEP_SYMBOL, to its return) then holds the step alone, never
 * the SysTick or UART handler that happened to interrupt it. The pending interrupt runs right after.
 */
#include <stdint.h>
#include <string.h>

#include "board.h"
#include "gainlink/gl_law.h"
#include "gl_clock.h"
#include "gl_nvic.h"
#include "gl_stream.h"
#include "gl_uart.h"
#include "semihost.h"
#if GL_IMAGE_SERVE
#include "serve.h"
#endif

#define GL_IN_MAGIC 0x32494C47u  /* "GLI2" */
#define GL_OUT_MAGIC 0x324F4C47u /* "GLO2" */
#ifndef GL_IMAGE_MAX_BLOCK
#define GL_IMAGE_MAX_BLOCK 64
#endif
#define GL_MAX_BLOCK ((uint32_t)GL_IMAGE_MAX_BLOCK)
#define GL_MAX_ARGS 16

static gl_law_t law;
static gl_law_sample_t in_buf[GL_MAX_BLOCK];
static gl_law_record_t out_buf[GL_MAX_BLOCK];
static gl_law_out_t last; /* the answer of the last step, idle period or reset (a stage record holds it) */

/* Staged sets, read alternately: a law that runs a set by address keeps running the one it accepted last while
 * the next is read and checked. */
static gl_law_gains_t staged[2];
static uint32_t stage_count;
static int running = -1; /* which of `staged` the law runs (-1: the compiled set) */

/** Read gl_stageK.bin (K = number of earlier stage records) into the set the law does not run and stage it. */
static gl_status_t stage_from_file(void)
{
    char name[24] = "gl_stage";
    char digits[10];
    size_t count = 0;
    uint32_t k = stage_count++;
    do {
        digits[count++] = (char)('0' + (k % 10u));
        k /= 10u;
    } while (k != 0u);
    size_t pos = 8;
    while (count > 0u) {
        name[pos++] = digits[--count];
    }
    memcpy(&name[pos], ".bin", 5);
    int32_t fd = gl_sh_open(name, GL_SH_MODE_RB);
    if (fd < 0) {
        return GL_ERR_NULL;
    }
    const int into = running == 0 ? 1 : 0;
    gl_status_t st = GL_ERR_NULL;
    if (gl_sh_read_all(fd, &staged[into], sizeof staged[into]) == 0) {
        st = gl_law_stage(&law, &staged[into]);
    }
    gl_sh_close(fd);
    if (st == GL_OK) {
        running = into;
    }
    return st;
}

static void uart_puts(const char *s)
{
    (void)gl_uart_write((const uint8_t *)s, strlen(s));
}

static void uart_hex(uint32_t v)
{
    static const char digits[] = "0123456789ABCDEF";
    char text[11] = "0x";
    for (int i = 0; i < 8; ++i) {
        text[2 + i] = digits[(v >> (28 - 4 * i)) & 0xFu];
    }
    text[10] = '\0';
    uart_puts(text);
}

static int uart_smoke(void)
{
    float y[GL_P];
    float r[GL_QA];
    float s[GL_LAW_EA];
    for (unsigned i = 0; i < GL_P; ++i) {
        y[i] = 0.5f;
    }
    memset(r, 0, sizeof r);
    memset(s, 0, sizeof s);
    gl_law_out_t out;
    gl_status_t st = gl_law_step(&law, y, r, s, &out);
    uart_puts("step ");
    uart_hex((uint32_t)st);
    for (unsigned i = 0; i < GL_M; ++i) {
        uint32_t bits;
        memcpy(&bits, &out.u[i], sizeof bits);
        uart_puts(" u=");
        uart_hex(bits);
    }
    uart_puts("\n");
    return gl_uart_flush(1000u) == 0 ? GL_EXIT_OK : GL_EXIT_IO;
}

/** `serve PROTOCOL OPTIONS...` after the program name: runs the server (returns only on a bad option); else -1. */
static int serve_if_asked(void)
{
    static char line[512];
    static char *words[GL_MAX_ARGS];
    int n = gl_sh_cmdline_words(line, sizeof line, words, GL_MAX_ARGS);
    if (n < 2 || strcmp(words[1], "serve") != 0) {
        return -1;
    }
#if !GL_IMAGE_SERVE
    uart_puts("error: this image carries no bus node (built without GL_IMAGE_SERVE)\n");
    return GL_EXIT_BAD_INPUT;
#else
    if (n >= 3 && strcmp(words[2], "mavlink") == 0) {
#if GL_IMAGE_SERVE_MAVLINK
        return gl_serve_mavlink(n - 3, &words[3]);
#else
        return gl_serve_refuse("this image carries the slcan node only (the micro:bit's RAM)");
#endif
    }
    if (n >= 3 && strcmp(words[2], "slcan") == 0) {
        return gl_serve_slcan(n - 3, &words[3]);
    }
    return gl_serve_refuse("serve needs a protocol: mavlink or slcan");
#endif
}

/** One input record through the law into its output record (a step, an idle period, a staged set or a reset). */
static void replay_record(const void *in_record, void *out_record)
{
    const gl_law_sample_t *in = (const gl_law_sample_t *)in_record;
    if (in->tag == GL_LAW_TAG_IDLE) {
        (void)gl_law_idle(&law, &last);
    } else if (in->tag == GL_LAW_TAG_RESET) {
        (void)gl_law_reset(&law, &last);
    } else if (in->tag == GL_LAW_TAG_STAGE) {
        last.status = (int32_t)stage_from_file(); /* the command held, as before the record */
        last.flags = 0u;
        last.sat = 0u;
    } else {
        const uint32_t primask = gl_irq_save();
        (void)gl_law_step(&law, in->y, GL_Q > 0 ? in->r : NULL, GL_LAW_E > 0 ? in->s : NULL, &last);
        gl_irq_restore(primask);
    }
    gl_law_record(&law, &last, (gl_law_record_t *)out_record);
}

/** The stream's start: a watchdog of at least one period, the built-in gains; the output header's words. */
static int replay_begin(const uint32_t in_hdr[4], uint32_t out_hdr[8])
{
    if (in_hdr[3] == 0u) {
        return GL_EXIT_BAD_INPUT;
    }
    if (gl_law_init(&law, in_hdr[3]) != GL_OK) {
        return GL_EXIT_GAINS;
    }
    memset(&last, 0, sizeof last);
    const uint32_t words[6] = {GL_LAW_ID, GL_N, GL_M, GL_P, GL_Q, GL_LAW_E};
    memcpy(&out_hdr[2], words, sizeof words);
    return GL_EXIT_OK;
}

static const gl_stream_t replay_stream = {
    .in_magic = GL_IN_MAGIC,
    .out_magic = GL_OUT_MAGIC,
    .in_size = sizeof(gl_law_sample_t),
    .out_size = sizeof(gl_law_record_t),
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
    uart_puts("gainlink ");
    uart_puts(gl_artifact_name);
    uart_puts(" ");
    uart_puts(gl_board_name);
    uart_puts(" sha256:");
    uart_puts(gl_artifact_sha256);
    uart_puts(" law=" GL_LAW_NAME " variant=" GL_LAW_VARIANT " wire=" GL_WIRE_VERSION_TEXT "\n");
    int served = serve_if_asked();
    if (served >= 0) {
        return served;
    }
    int32_t fin = gl_sh_open("gl_in.bin", GL_SH_MODE_RB);
    if (fin < 0) {
        if (gl_law_init(&law, GL_WATCHDOG_PERIODS_DEFAULT) != GL_OK) {
            return GL_EXIT_GAINS;
        }
        return uart_smoke();
    }
    int rc = gl_stream_replay(fin, &replay_stream);
    gl_sh_close(fin);
    return rc;
}

int main(void)
{
    int rc = run();
    (void)gl_uart_flush(1000u); /* what is still queued on the UART goes out before the simulator stops */
    return rc;
}
