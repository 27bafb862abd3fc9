/**
 * @file main.c
 * @brief Host executable `gainlink_loop_host`: the control loop driven by text lines on stdin.
 *
 * Prints one banner line `gainlink-loop NAME sha256:HEX n m p q`, then answers each input line:
 * - `y0 .. y{p-1} r0 .. r{q-1}` (numbers, `nan`/`inf` allowed) -> `step STATUS u.. SATMASK xh.. z..`
 * - `idle`  -> `idle STATUS u..` (a period without a measurement: watchdog)
 * - `reset` -> `reset STATUS`
 * - `stage` -> `stage STATUS` (re-stages the built-in gain set through the double buffer)
 * - `crc`   -> `crc 0xHEX` (checksum of the running gain set)
 * Numbers are separated by spaces, tabs or commas. Floats are printed round-trip (%.9g). Each answer is flushed at
 * once. A malformed line answers `error ...`, changes nothing, and the loop goes on; at the end of stdin the
 * executable exits with status 2 if any line was, after one line on stderr saying how many and which came first.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gainlink/gl_loop.h"

static gl_loop_t loop;

static void print_floats(const float *x, size_t count)
{
    for (size_t i = 0; i < count; ++i) {
        printf(" %.9g", (double)x[i]);
    }
}

static int parse_sample(char *line, float *out, size_t count)
{
    char *cursor = line;
    for (size_t i = 0; i < count; ++i) {
        char *end = NULL;
        out[i] = strtof(cursor, &end);
        if (end == cursor) {
            return -1;
        }
        cursor = end;
        while (*cursor == ' ' || *cursor == ',' || *cursor == '\t') {
            ++cursor;
        }
    }
    return (*cursor == '\0' || *cursor == '\n' || *cursor == '\r') ? 0 : -1;
}

int main(void)
{
    gl_status_t st = gl_loop_init(&loop, &gl_gains_default, GL_WATCHDOG_PERIODS_DEFAULT);
    if (st != GL_OK) {
        fprintf(stderr, "gainlink_loop_host: built-in gains rejected (status %d)\n", (int)st);
        return 3;
    }
    printf("gainlink-loop %s sha256:%s %d %d %d %d\n", gl_artifact_name, gl_artifact_sha256, GL_N, GL_M, GL_P, GL_Q);
    fflush(stdout);
    char line[4096];
    float sample[GL_P + GL_QA];
    float u[GL_M];
    unsigned long lines = 0, refused = 0, first_refused = 0;
    while (fgets(line, sizeof line, stdin) != NULL) {
        ++lines;
        if (strncmp(line, "idle", 4) == 0) {
            st = gl_loop_idle(&loop, u);
            printf("idle %d", (int)st);
            print_floats(u, GL_M);
        } else if (strncmp(line, "reset", 5) == 0) {
            printf("reset %d", (int)gl_loop_reset(&loop));
        } else if (strncmp(line, "stage", 5) == 0) {
            printf("stage %d", (int)gl_loop_stage(&loop, &gl_gains_default));
        } else if (strncmp(line, "crc", 3) == 0) {
            printf("crc 0x%08lX", (unsigned long)gl_loop_active_crc32(&loop));
        } else if (parse_sample(line, sample, GL_P + GL_Q) == 0) {
            st = gl_loop_step(&loop, sample, GL_Q > 0 ? &sample[GL_P] : NULL, u);
            printf("step %d", (int)st);
            print_floats(u, GL_M);
            printf(" %lu", (unsigned long)loop.sat_mask);
            print_floats(loop.xh, GL_N);
            print_floats(loop.z, GL_Q);
        } else {
            printf("error expected %d numbers, idle, reset, stage or crc", GL_P + GL_Q);
            if (++refused == 1) {
                first_refused = lines;
            }
        }
        printf("\n");
        fflush(stdout);
    }
    if (refused > 0) {
        fprintf(stderr, "gainlink_loop_host: %lu of %lu input lines unreadable (the first: line %lu)\n", refused, lines,
                first_refused);
        return 2;
    }
    return 0;
}
