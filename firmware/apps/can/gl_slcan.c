/**
 * @file gl_slcan.c
 * @brief Lawicel/slcan line parser and frame formatter (see gl_slcan.h).
 */
#include "gl_slcan.h"

#include "gainlink/gl_hex.h"

#include <string.h>

static const uint8_t OK[] = "\r";
static const uint8_t BEL[] = "\a";
static const char hex_digits[] = "0123456789ABCDEF";

static void inc(uint32_t *counter)
{
    if (*counter != UINT32_MAX) {
        ++*counter;
    }
}

void gl_slcan_init(gl_slcan_t *s, const gl_slcan_port_t *port)
{
    memset(s, 0, sizeof *s);
    s->port = *port;
}

static void reply(gl_slcan_t *s, const uint8_t *bytes, size_t len)
{
    (void)s->port.write(s->port.ctx, bytes, len);
}

static void refuse(gl_slcan_t *s)
{
    inc(&s->stats.refused);
    reply(s, BEL, 1);
}

/** Parse `digits` hex digits at `text`; -1 when one is not a hex digit. */
static int parse_hex(const char *text, uint32_t digits, uint32_t *out)
{
    uint64_t v;
    if (gl_hex_parse(text, digits, &v) != 0) {
        return -1;
    }
    *out = (uint32_t)v;
    return 0;
}

/**
 * A data or remote frame line (`t`, `T`, `r`, `R`): checks it and, for a standard data frame, fills `frame`.
 * Returns 1 for a deliverable standard data frame, 0 for a well-formed frame that is not delivered, -1 when malformed.
 */
static int parse_frame(const char *line, uint32_t len, gl_can_frame_t *frame)
{
    int extended = line[0] == 'T' || line[0] == 'R';
    int remote = line[0] == 'r' || line[0] == 'R';
    uint32_t id_digits = extended ? 8u : 3u;
    uint32_t id, dlc;
    if (len < 2u + id_digits || parse_hex(&line[1], id_digits, &id) != 0 ||
        parse_hex(&line[1 + id_digits], 1u, &dlc) != 0 || dlc > 8u) {
        return -1;
    }
    if (id > (extended ? 0x1FFFFFFFu : 0x7FFu) || len != 2u + id_digits + (remote ? 0u : 2u * dlc)) {
        return -1;
    }
    memset(frame, 0, sizeof *frame);
    frame->id = id;
    frame->len = (uint8_t)dlc;
    for (uint32_t i = 0; i < (remote ? 0u : dlc); ++i) {
        uint32_t byte;
        if (parse_hex(&line[2 + id_digits + 2u * i], 2u, &byte) != 0) {
            return -1;
        }
        frame->data[i] = (uint8_t)byte;
    }
    return (extended || remote) ? 0 : 1;
}

static void handle_frame_line(gl_slcan_t *s)
{
    gl_can_frame_t frame;
    int r = parse_frame(s->line, s->len, &frame);
    if (r < 0 || !s->open) {
        refuse(s);
        return;
    }
    const uint8_t *ack = (s->line[0] == 'T' || s->line[0] == 'R') ? (const uint8_t *)"Z\r" : (const uint8_t *)"z\r";
    reply(s, ack, 2);
    if (r == 1) {
        inc(&s->stats.frames_in);
        s->port.frame(s->port.ctx, &frame);
    }
}

static void handle_status(gl_slcan_t *s)
{
    uint32_t overruns = s->port.overruns != NULL ? s->port.overruns(s->port.ctx) : 0u;
    uint8_t flags = overruns != s->overruns_seen ? 0x08u : 0x00u;
    s->overruns_seen = overruns;
    uint8_t out[4] = {'F', (uint8_t)hex_digits[flags >> 4], (uint8_t)hex_digits[flags & 0xFu], '\r'};
    reply(s, out, sizeof out);
}

/** Commands that only change the channel state; returns 1 when handled. */
static int handle_state(gl_slcan_t *s)
{
    const char *l = s->line;
    switch (l[0]) {
    case 'S':
        if (s->len == 2u && l[1] >= '0' && l[1] <= '8' && !s->open) {
            reply(s, OK, 1);
        } else {
            refuse(s);
        }
        return 1;
    case 's': {
        uint32_t btr;
        if (s->len == 5u && parse_hex(&l[1], 4u, &btr) == 0 && !s->open) {
            reply(s, OK, 1);
        } else {
            refuse(s);
        }
        return 1;
    }
    case 'O':
    case 'L':
        if (s->len == 1u && !s->open) {
            s->open = 1;
            s->listen_only = l[0] == 'L';
            reply(s, OK, 1);
        } else {
            refuse(s);
        }
        return 1;
    case 'C':
        s->open = 0;
        s->listen_only = 0;
        reply(s, OK, 1);
        return 1;
    default: return 0;
    }
}

static void handle_line(gl_slcan_t *s)
{
    const char *l = s->line;
    if (s->len == 0u) {
        reply(s, OK, 1);
        return;
    }
    if (handle_state(s)) {
        return;
    }
    switch (l[0]) {
    case 't':
    case 'T':
    case 'r':
    case 'R': handle_frame_line(s); break;
    case 'V': reply(s, (const uint8_t *)"V1013\r", 6); break;
    case 'N': reply(s, (const uint8_t *)"NGL00\r", 6); break;
    case 'F': handle_status(s); break;
    case 'Z':
        if (s->len == 2u && l[1] == '0') {
            reply(s, OK, 1);
        } else {
            refuse(s);
        }
        break;
    default: refuse(s); break;
    }
}

void gl_slcan_input(gl_slcan_t *s, const uint8_t *bytes, size_t len)
{
    for (size_t i = 0; i < len; ++i) {
        uint8_t c = bytes[i];
        if (c == '\n') {
            continue;
        }
        if (c == '\r') {
            if (s->overlong) {
                refuse(s);
            } else {
                handle_line(s);
            }
            s->len = 0;
            s->overlong = 0;
        } else if (s->len < GL_SLCAN_LINE_MAX) {
            s->line[s->len++] = (char)c;
        } else {
            s->overlong = 1;
        }
    }
}

int gl_slcan_send(gl_slcan_t *s, const gl_can_frame_t *frame)
{
    if (!s->open || s->listen_only || frame->fd || frame->id > 0x7FFu || frame->len > 8u) {
        inc(&s->stats.not_sent);
        return -1;
    }
    uint8_t out[1 + 3 + 1 + 16 + 1];
    size_t at = 0;
    out[at++] = 't';
    out[at++] = (uint8_t)hex_digits[(frame->id >> 8) & 0xFu];
    out[at++] = (uint8_t)hex_digits[(frame->id >> 4) & 0xFu];
    out[at++] = (uint8_t)hex_digits[frame->id & 0xFu];
    out[at++] = (uint8_t)('0' + frame->len);
    for (uint32_t i = 0; i < frame->len; ++i) {
        out[at++] = (uint8_t)hex_digits[frame->data[i] >> 4];
        out[at++] = (uint8_t)hex_digits[frame->data[i] & 0xFu];
    }
    out[at++] = '\r';
    if (s->port.write(s->port.ctx, out, at) != 0) {
        inc(&s->stats.not_sent);
        return -1;
    }
    inc(&s->stats.frames_out);
    return 0;
}
