/**
 * @file fixed_main.c
 * @brief Host executable `gainlink_fixed_loop_host`: the fixed-point loop (gl_fixed.h) driven by text lines on stdin.
 *
 * The same input as the float loop's main.c: after one banner line `gainlink-fixed NAME sha256:HEX`, each input
 * line is answered by one line, flushed at once (a program may drive it line by line through pipes):
 * - `y0 .. y{p-1} r0 .. r{q-1}` (decimal numbers read as float, separated by spaces, tabs or commas; `nan`, `inf`
 *   allowed) -> `step FLAGS SAT CLIP OVERFLOW U.. V.. XH.. Z..` (integers: the command, unsaturated command, estimate
 *   and integrator words)
 * - `reset` -> `reset 0` (the loop restarts from its initial state)
 * - `idle`, `stage`, `crc` (the float loop's watchdog, gain staging and checksum) -> `error ...`: not in this loop
 * - anything else -> `error expected N numbers or reset`
 * A line answered `error` changes nothing and the loop goes on; at the end of stdin the executable exits with
 * status 2 if any line was, after one line on stderr saying how many and which came first, else 0.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gl_fixed_record.h"

static int parse(char *line, float *vals, int count)
{
    char *p = line;
    for (int i = 0; i < count; ++i) {
        char *end;
        vals[i] = strtof(p, &end);
        if (end == p) {
            return -1;
        }
        p = end;
        while (*p == ' ' || *p == ',' || *p == '\t') {
            ++p;
        }
    }
    return (*p == '\0' || *p == '\n' || *p == '\r') ? 0 : -1;
}

static void print_record(const gl_fixed_record_t *o)
{
    printf("step %u %u %u %u", (unsigned)o->flags, (unsigned)o->sat_mask, (unsigned)o->clip_mask,
           (unsigned)o->overflow_mask);
    for (int i = 0; i < GL_FX_M; ++i) {
        printf(" %ld", (long)o->U[i]);
    }
    for (int i = 0; i < GL_FX_M; ++i) {
        printf(" %ld", (long)o->V[i]);
    }
    for (int i = 0; i < GL_FX_N; ++i) {
        printf(" %ld", (long)o->XH[i]);
    }
    for (int i = 0; i < GL_FX_Q; ++i) {
        printf(" %ld", (long)o->Z[i]);
    }
}

int main(void)
{
    static gl_fixed_loop_t loop;
    char line[4096]; /* as main.c's */
    float vals[GL_FX_P + GL_FX_QA];
    float u[GL_FX_M];
    gl_fixed_record_t rec;
    unsigned long lines = 0, refused = 0, first_refused = 0;
    (void)gl_fixed_init(&loop, &gl_fixed_gains_default);
    printf("gainlink-fixed %s sha256:%s\n", GL_FX_NAME, GL_FX_ARTIFACT_SHA256);
    fflush(stdout);
    while (fgets(line, sizeof line, stdin) != NULL) {
        ++lines;
        if (strncmp(line, "reset", 5) == 0) {
            gl_fixed_reset(&loop);
            printf("reset 0");
        } else if (strncmp(line, "idle", 4) == 0 || strncmp(line, "stage", 5) == 0 || strncmp(line, "crc", 3) == 0) {
            printf("error %.*s: a command of the float32 loop, not of the fixed-point loop", (int)strcspn(line, " \r\n"),
                   line);
            if (++refused == 1) {
                first_refused = lines;
            }
        } else if (parse(line, vals, GL_FX_P + GL_FX_Q) == 0) {
            (void)gl_fixed_step(&loop, vals, &vals[GL_FX_P], u);
            gl_fixed_record(&loop, u, &rec);
            print_record(&rec);
        } else {
            printf("error expected %d numbers or reset", GL_FX_P + GL_FX_Q);
            if (++refused == 1) {
                first_refused = lines;
            }
        }
        printf("\n");
        fflush(stdout);
    }
    if (refused > 0) {
        fprintf(stderr, "gainlink_fixed_loop_host: %lu of %lu input lines unreadable (the first: line %lu)\n", refused,
                lines, first_refused);
        return 2;
    }
    return 0;
}
