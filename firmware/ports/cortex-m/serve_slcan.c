/**
 * @file serve_slcan.c
 * @brief The CAN node (apps/can/gl_can_node.h) behind an slcan adapter (apps/can/gl_slcan.h) on the
 *        console UART: `can.Bus(interface="slcan", channel="socket://HOST:PORT")` exchanges the same DBC
 *        frames with it as with the host CAN app (classic frames: slcan has no CAN FD). It runs the build's law
 *        (gl_law.h), which its ready line names with the wire format (`law=q31 wire=4`; a scheduled law's external
 *        sigma travels after the references).
 */
#include <math.h>
#include <string.h>

#include "gainlink/gl_hex.h"
#include "gl_can_node.h"
#include "gl_nvic.h"
#include "gl_slcan.h"
#include "gl_uart.h"
#include "semihost.h"
#include "serve.h"

/* The ready line names the law and the wire format, as the host app's does. */
#define LAW_FIELD " law=" GL_LAW_NAME " wire=" GL_WIRE_VERSION_TEXT

static gl_can_node_t node;
static gl_slcan_t slcan;
static gl_can_node_config_t cfg;

static int uart_write(void *ctx, const uint8_t *bytes, size_t len)
{
    (void)ctx;
    return gl_uart_write(bytes, len);
}

static uint32_t uart_overruns(void *ctx)
{
    (void)ctx;
    gl_uart_stats_t s;
    gl_uart_stats(&s);
    return s.rx_overruns;
}

static void frame_in(void *ctx, const gl_can_frame_t *frame)
{
    (void)ctx;
    (void)gl_can_node_frame(&node, frame);
}

static int frame_out(void *ctx, const gl_can_frame_t *frame)
{
    (void)ctx;
    return gl_slcan_send(&slcan, frame);
}

/** 16 hex digits -> the double with those bits; advances `*text`. */
static int parse_double_bits(const char **text, double *out)
{
    uint64_t bits;
    if (gl_hex_parse(*text, 16u, &bits) != 0) {
        return -1;
    }
    *text += 16;
    memcpy(out, &bits, sizeof *out);
    return 0;
}

/** Exactly `count` `F:O` pairs separated by '/'; factors finite and > 0, offsets finite. */
static int parse_scales(const char *text, gl_can_scale_t *scales, uint32_t count)
{
    for (uint32_t i = 0; i < count; ++i) {
        double f, o;
        if (parse_double_bits(&text, &f) != 0 || *text++ != ':' || parse_double_bits(&text, &o) != 0) {
            return -1;
        }
        if (!(f > 0.0) || !isfinite(f) || !isfinite(o)) {
            return -1;
        }
        scales[i].factor = f;
        scales[i].offset = o;
        if (*text != (i + 1u < count ? '/' : '\0')) {
            return -1;
        }
        ++text;
    }
    return 0;
}

static int parse_options(int argc, char *const argv[], const char **meas, const char **cmd)
{
    uint32_t base = 0x100;
    for (int i = 0; i < argc; ++i) {
        const char *v;
        if (gl_serve_option(argv[i], "base", &v)) {
            if (gl_serve_number(v, 0x7FFu - 0x30u, &base) != 0) {
                return gl_serve_refuse("base must leave room for the layout (0..0x7cf)");
            }
        } else if (gl_serve_option(argv[i], "encoding", &v)) {
            if (strcmp(v, "float32") == 0) {
                cfg.encoding = GL_CAN_FLOAT32;
            } else if (strcmp(v, "int16") == 0) {
                cfg.encoding = GL_CAN_INT16;
            } else {
                return gl_serve_refuse("encoding must be float32 or int16");
            }
        } else if (gl_serve_option(argv[i], "meas", &v)) {
            *meas = v;
        } else if (gl_serve_option(argv[i], "cmd", &v)) {
            *cmd = v;
        } else {
            return gl_serve_refuse("unknown slcan option (base= encoding= meas= cmd=)");
        }
    }
    cfg.base_id = base;
    return 0;
}

int gl_serve_slcan(int argc, char *const argv[])
{
    const char *meas = NULL, *cmd = NULL;
    cfg.encoding = GL_CAN_FLOAT32;
    int rc = parse_options(argc, argv, &meas, &cmd);
    if (rc != 0) {
        return rc;
    }
    if (cfg.encoding == GL_CAN_INT16) {
        if (meas == NULL || cmd == NULL || parse_scales(meas, cfg.meas_scale, GL_CAN_NODE_SAMPLE) != 0 ||
            parse_scales(cmd, cfg.cmd_scale, GL_M) != 0) {
            return gl_serve_refuse("int16 needs meas= (outputs then references) and cmd= (inputs) as F:O/F:O/... "
                                   "with the 16 hex digits of each double");
        }
    } else if (meas != NULL || cmd != NULL) {
        return gl_serve_refuse("meas= and cmd= need encoding=int16");
    }
    cfg.fd = 0;
    cfg.watchdog_periods = GL_WATCHDOG_PERIODS_DEFAULT;
    cfg.send = frame_out;
    if (gl_can_node_init(&node, &cfg) != GL_OK) {
        (void)gl_serve_refuse("gain set rejected");
        return GL_EXIT_GAINS;
    }
    const gl_slcan_port_t port = {.ctx = 0, .write = uart_write, .frame = frame_in, .overruns = uart_overruns};
    gl_slcan_init(&slcan, &port);
    static const char ready_f32[] = "ready slcan encoding=float32" LAW_FIELD "\n";
    static const char ready_i16[] = "ready slcan encoding=int16" LAW_FIELD "\n";
    if (cfg.encoding == GL_CAN_INT16) {
        (void)gl_uart_write((const uint8_t *)ready_i16, sizeof ready_i16 - 1u);
    } else {
        (void)gl_uart_write((const uint8_t *)ready_f32, sizeof ready_f32 - 1u);
    }
    for (;;) {
        uint8_t buf[64];
        size_t n;
        while ((n = gl_uart_read(buf, sizeof buf)) > 0u) {
            gl_slcan_input(&slcan, buf, n);
        }
        gl_wait_for_interrupt(gl_uart_rx_ready);
    }
}
