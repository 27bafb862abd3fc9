/**
 * @file fuzz_gains_stage.c
 * @brief libFuzzer harness: the gain staging/commit path (gl_loop_stage -> gl_gains_check -> gl_coeffs_derive).
 *
 * The candidate set starts as the artifact's compiled set; byte 0 chooses how the input changes it:
 * bit 0 set: the input overlays the raw bytes of the whole gl_gains_t (dimensions and crc32 included);
 * clear: the input is a list of edits (uint16 float index, float32 value), one parameter at a time as a
 * MAVLink PARAM_SET stages it. Bit 1 set: the candidate is sealed with its own CRC (a well-formed upload
 * of hostile numbers), so the checks past the CRC are reached. Then one step runs on a finite sample.
 * Oracles besides ASan/UBSan: the stage returns what gl_gains_check() says unless the derivation overflows;
 * a refused set leaves the running set, its checksum and the pending flag as they were; an accepted set
 * runs from the next step (checksum, swap count); the command of that step is within the set's limits.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "gainlink/gl_loop.h"

#define PAYLOAD_FLOATS ((size_t)(GL_GAINS_FLOATS))

static gl_loop_t loop;

static void apply_edits(gl_gains_t *g, const uint8_t *data, size_t size)
{
    float *payload = &g->Ts;
    for (size_t at = 0; at + 6u <= size; at += 6u) {
        uint16_t index;
        memcpy(&index, &data[at], sizeof index);
        memcpy(&payload[index % PAYLOAD_FLOATS], &data[at + 2u], sizeof(float));
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1u) {
        return 0;
    }
    const uint8_t mode = data[0];
    gl_gains_t cand = gl_gains_default;
    if (mode & 1u) {
        memcpy(&cand, &data[1], size - 1u < sizeof cand ? size - 1u : sizeof cand);
    } else {
        apply_edits(&cand, &data[1], size - 1u);
    }
    if (mode & 2u) {
        cand.crc32 = gl_gains_crc32(&cand);
    }
    if (gl_loop_init(&loop, &gl_gains_default, 3u) != GL_OK) {
        abort();
    }
    const uint32_t crc_before = gl_loop_active_crc32(&loop);
    const gl_status_t check = gl_gains_check(&cand);
    const gl_status_t st = gl_loop_stage(&loop, &cand);
    if (check != GL_OK && st != check) {
        abort();
    }
    if (check == GL_OK && st != GL_OK && st != GL_ERR_NANINF) {
        abort(); /* a set that passes the check can only fail on non-finite derived coefficients */
    }
    float y[GL_P] = {0};
    float r[GL_QA] = {0};
    float u[GL_M];
    for (size_t i = 0; i < GL_P; ++i) {
        y[i] = 0.25f * (float)(i + 1u);
    }
    (void)gl_loop_step(&loop, y, r, u);
    if (st != GL_OK) {
        if (loop.pending != 0u || loop.swaps != 0u || gl_loop_active_crc32(&loop) != crc_before) {
            abort();
        }
        return 0;
    }
    if (loop.swaps != 1u || gl_loop_active_crc32(&loop) != cand.crc32) {
        abort();
    }
    for (size_t i = 0; i < GL_M; ++i) {
        if (!(u[i] >= cand.u_min[i] && u[i] <= cand.u_max[i])) {
            abort(); /* a committed set must never command outside its limits, whatever its numbers */
        }
    }
    return 0;
}
