/**
 * @file gl_stream.c
 * @brief The semihosting replay/PIL stream shared by the Cortex-M images (gl_stream.h).
 */
#include "gl_stream.h"

#include <stddef.h>

#include "semihost.h"

/** The records after the headers, `block` at a time: read, run through the loop, write. */
static int replay_records(int32_t fin, int32_t fout, uint32_t count, uint32_t block, const gl_stream_t *s)
{
    uint8_t *in = (uint8_t *)s->in_buf;
    uint8_t *out = (uint8_t *)s->out_buf;
    for (uint32_t done = 0; done < count;) {
        const uint32_t chunk = (count - done) < block ? (count - done) : block;
        if (gl_sh_read_all(fin, in, (size_t)chunk * s->in_size) != 0) {
            return GL_EXIT_IO;
        }
        for (uint32_t k = 0; k < chunk; ++k) {
            s->record(in + (size_t)k * s->in_size, out + (size_t)k * s->out_size);
        }
        if (gl_sh_write_all(fout, out, (size_t)chunk * s->out_size) != 0) {
            return GL_EXIT_IO;
        }
        done += chunk;
    }
    return GL_EXIT_OK;
}

int gl_stream_replay(int32_t fin, const gl_stream_t *s)
{
    uint32_t hdr[4];
    if (gl_sh_read_all(fin, hdr, sizeof hdr) != 0) {
        return GL_EXIT_IO;
    }
    if (hdr[0] != s->in_magic || hdr[2] == 0u) {
        return GL_EXIT_BAD_INPUT;
    }
    uint32_t out_hdr[8] = {s->out_magic, hdr[1], 0u, 0u, 0u, 0u, 0u, 0u};
    int rc = s->begin(hdr, out_hdr);
    if (rc != GL_EXIT_OK) {
        return rc;
    }
    int32_t fout = gl_sh_open("gl_out.bin", GL_SH_MODE_WB);
    if (fout < 0) {
        return GL_EXIT_IO;
    }
    if (gl_sh_write_all(fout, out_hdr, sizeof out_hdr) != 0) {
        return GL_EXIT_IO;
    }
    const uint32_t block = hdr[2] < s->max_block ? hdr[2] : s->max_block;
    rc = replay_records(fin, fout, hdr[1], block, s);
    if (rc == GL_EXIT_OK) {
        gl_sh_close(fout);
    }
    return rc;
}
