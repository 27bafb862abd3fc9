/**
 * @file gl_mav_store.c
 * @brief Encode and decode the committed gain set as `ID BITS` text (see gl_mav_store.h).
 *
 * No stdio and no float formatting: the values travel as their bit patterns, so the same code runs on
 * the host and on a microcontroller and a stored set comes back bit for bit.
 */
#include "gl_mav_store.h"

#include "gainlink/gl_hex.h"

#include <string.h>

static const char header[] = "# gainlink MAVLink parameters: committed gain set of the " GL_LAW_NAME
                             " law, each value's 32 bits in hex\n";
static const char hex_digits[] = "0123456789abcdef";

static size_t put_line(uint8_t *out, size_t at, size_t cap, const char *id, uint32_t bits)
{
    size_t id_len = 0;
    while (id_len < GL_MAV_ID_LEN && id[id_len] != '\0') {
        ++id_len;
    }
    if (at + id_len + 10u > cap) {
        return 0;
    }
    memcpy(&out[at], id, id_len);
    at += id_len;
    out[at++] = ' ';
    for (int shift = 28; shift >= 0; shift -= 4) {
        out[at++] = (uint8_t)hex_digits[(bits >> shift) & 0xFu];
    }
    out[at++] = '\n';
    return at;
}

size_t gl_mav_store_encode(const gl_mav_params_t *table, uint8_t *buf, size_t cap)
{
    size_t at = sizeof header - 1u;
    if (cap < at) {
        return 0;
    }
    memcpy(buf, header, at);
    for (uint16_t k = 0; k < table->count; ++k) {
        const gl_mav_param_t *p = &table->param[k];
        if (p->kind != GL_MAV_PARAM_GAIN) {
            continue;
        }
        at = put_line(buf, at, cap, p->id, gl_mav_params_bits(&table->committed, p));
        if (at == 0u) {
            return 0;
        }
    }
    return put_line(buf, at, cap, "GL_HASH", table->committed.crc32);
}

static int parse_bits(const uint8_t *text, size_t len, uint32_t *bits)
{
    uint64_t v;
    if (len != 8u || gl_hex_parse((const char *)text, len, &v) != 0) {
        return -1;
    }
    *bits = (uint32_t)v;
    return 0;
}

/**
 * Index of parameter `id`: `*next` first (gl_mav_store_encode() writes the lines in index order, so a stored
 * set decodes in one pass instead of a search per line), else a search; `*next` becomes the one after it.
 */
static int32_t find_param(const gl_mav_params_t *table, const char *id, int32_t *next)
{
    int32_t k = *next;
    if (k < 0 || k >= (int32_t)table->count || strncmp(table->param[k].id, id, GL_MAV_ID_LEN) != 0) {
        k = gl_mav_params_find(table, id);
    }
    *next = k + 1;
    return k;
}

/** Apply one `ID BITS` line to `candidate`; returns GL_MAV_STORE_OK or the line's error. */
static gl_mav_store_error_t apply_line(const gl_mav_params_t *table, const uint8_t *line, size_t len,
                                       gl_mav_set_t *candidate, int *have_hash, int32_t *next)
{
    const uint8_t *space = memchr(line, ' ', len);
    if (space == NULL || space == line || (size_t)(space - line) > GL_MAV_ID_LEN) {
        return GL_MAV_STORE_E_SYNTAX;
    }
    char id[GL_MAV_ID_LEN + 1] = {0};
    memcpy(id, line, (size_t)(space - line));
    uint32_t bits;
    if (parse_bits(space + 1, len - (size_t)(space - line) - 1u, &bits) != 0) {
        return GL_MAV_STORE_E_NUMBER;
    }
    if (strcmp(id, "GL_HASH") == 0) {
        candidate->crc32 = bits;
        *have_hash = 1;
        return GL_MAV_STORE_OK;
    }
    int32_t k = find_param(table, id, next);
    if (k < 0 || table->param[k].kind != GL_MAV_PARAM_GAIN) {
        return GL_MAV_STORE_E_UNKNOWN;
    }
    return gl_mav_params_put_bits(candidate, &table->param[k], bits) == 0 ? GL_MAV_STORE_OK : GL_MAV_STORE_E_RANGE;
}

gl_mav_store_result_t gl_mav_store_decode(gl_mav_params_t *table, const uint8_t *buf, size_t len)
{
    gl_mav_store_result_t res = {.error = GL_MAV_STORE_OK, .line = 0, .status = 0};
    gl_mav_set_t candidate = table->committed;
    int have_hash = 0;
    int32_t next = 0;
    size_t at = 0;
    while (at < len) {
        const uint8_t *nl = memchr(&buf[at], '\n', len - at);
        size_t end = nl != NULL ? (size_t)(nl - buf) : len;
        res.line++;
        size_t line_len = end - at;
        if (line_len > 0u && buf[end - 1u] == '\r') {
            line_len--;
        }
        if (line_len > 0u && buf[at] != '#') {
            res.error = apply_line(table, &buf[at], line_len, &candidate, &have_hash, &next);
            if (res.error != GL_MAV_STORE_OK) {
                return res;
            }
        }
        at = end + 1u;
    }
    res.line = 0;
    if (!have_hash) {
        res.error = GL_MAV_STORE_E_NO_HASH;
        return res;
    }
    gl_status_t st = gl_mav_params_replace(table, &candidate);
    if (st != GL_OK) {
        res.error = GL_MAV_STORE_E_REFUSED;
        res.status = (int32_t)st;
    }
    return res;
}

const char *gl_mav_store_strerror(gl_mav_store_error_t error)
{
    switch (error) {
    case GL_MAV_STORE_OK: return "ok";
    case GL_MAV_STORE_E_SYNTAX: return "expected 'ID BITS'";
    case GL_MAV_STORE_E_UNKNOWN: return "unknown parameter";
    case GL_MAV_STORE_E_NUMBER: return "value is not 8 hex digits";
    case GL_MAV_STORE_E_NO_HASH: return "no GL_HASH line";
    case GL_MAV_STORE_E_REFUSED: return "stored set refused by the loop's checks";
    case GL_MAV_STORE_E_RANGE: return "an integer beyond its parameter's word";
    default: return "unknown error";
    }
}
