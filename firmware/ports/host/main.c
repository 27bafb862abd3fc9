/**
 * @file main.c
 * @brief Host executable `gainlink_loop_host`: the build's law (gl_law.h) driven by text lines on stdin.
 *
 * Prints one banner line `gainlink-loop NAME sha256:HEX n m p q law=LAW variant=VARIANT wire=N`, then answers each
 * input line:
 * - `y0 .. y{p-1} r0 .. r{q-1} [s0 .. s{e-1}]` (numbers, `nan`/`inf` allowed; s: a scheduled law's external
 *   scheduling signals) -> `step` and the step's record (gl_record_<law>.h, generated from the law's one description,
 *   gainlink.shipping.records): every field in order, integers in decimal, floats round-trip (%.9g)
 * - `idle`  -> `idle` and the record (a period without a measurement: the watchdog)
 * - `reset` -> `reset` and the record
 * - `stage` -> `stage STATUS` (re-stages the built-in gain set: the law's checks and swap)
 * - `crc`   -> `crc 0xHEX` (checksum of the running gain set)
 * Numbers are separated by spaces, tabs or commas. A malformed line answers `error ...`, changes nothing, and the
 * loop goes on; at the end of stdin the executable exits with status 2 if any line was, after one line on stderr
 * saying how many and which came first. Every answer is flushed at once, so a program can drive it line by line
 * through pipes (`gainlink firmware run`).
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gainlink/gl_law.h"

/** Values of a sample line: outputs, references, external signals. */
#define GL_SAMPLE_VALUES (GL_P + GL_Q + GL_LAW_E)

static gl_law_t law;

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

/* One field of the record: its used elements, as the kind says. */
static void print_field(const void *base, char kind, unsigned used)
{
    for (unsigned i = 0; i < used; ++i) {
        const char *at = (const char *)base + 4u * i;
        if (kind == 'f') {
            float v;
            memcpy(&v, at, sizeof v);
            printf(" %.9g", (double)v);
        } else if (kind == 'i') {
            int32_t v;
            memcpy(&v, at, sizeof v);
            printf(" %ld", (long)v);
        } else {
            uint32_t v;
            memcpy(&v, at, sizeof v);
            printf(" %lu", (unsigned long)v);
        }
    }
}

static void print_record(const char *what, const gl_law_out_t *out)
{
    gl_law_record_t rec;
    gl_law_record(&law, out, &rec);
    printf("%s", what);
#define GL_PRINT_FIELD(name, kind, used) print_field(&rec.name, kind, used);
    GL_LAW_RECORD_FIELDS(GL_PRINT_FIELD)
#undef GL_PRINT_FIELD
}

int main(void)
{
    gl_status_t st = gl_law_init(&law, GL_WATCHDOG_PERIODS_DEFAULT);
    if (st != GL_OK) {
        fprintf(stderr, "gainlink_loop_host: built-in gains rejected (status %d)\n", (int)st);
        return 3;
    }
    printf("gainlink-loop %s sha256:%s %d %d %d %d law=%s variant=%s wire=%d\n", gl_artifact_name, gl_artifact_sha256,
           GL_N, GL_M, GL_P, GL_Q, GL_LAW_NAME, GL_LAW_VARIANT, GL_WIRE_VERSION);
    fflush(stdout);
    char line[4096];
    float sample[GL_SAMPLE_VALUES];
    const float *r = GL_Q > 0 ? &sample[GL_P] : NULL;
    const float *s = GL_LAW_E > 0 ? &sample[GL_P + GL_Q] : NULL;
    gl_law_out_t out;
    unsigned long lines = 0, refused = 0, first_refused = 0;
    while (fgets(line, sizeof line, stdin) != NULL) {
        ++lines;
        if (strncmp(line, "idle", 4) == 0) {
            (void)gl_law_idle(&law, &out);
            print_record("idle", &out);
        } else if (strncmp(line, "reset", 5) == 0) {
            (void)gl_law_reset(&law, &out);
            print_record("reset", &out);
        } else if (strncmp(line, "stage", 5) == 0) {
            printf("stage %d", (int)gl_law_stage(&law, GL_LAW_DEFAULT_GAINS));
        } else if (strncmp(line, "crc", 3) == 0) {
            printf("crc 0x%08lX", (unsigned long)gl_law_active_crc32(&law));
        } else if (parse_sample(line, sample, GL_SAMPLE_VALUES) == 0) {
            (void)gl_law_step(&law, sample, r, s, &out);
            print_record("step", &out);
        } else {
            printf("error expected %d numbers, idle, reset, stage or crc", GL_SAMPLE_VALUES);
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
