/**
 * @file fixed_main.c
 * @brief Host executable of the fixed-point loop (gl_fixed.h), text in and out, for runs under ASan/UBSan.
 *
 * Each input line holds GL_FX_P samples then GL_FX_Q references (decimal, read as float; `nan`, `inf` allowed);
 * each step prints `step FLAGS SAT CLIP OVERFLOW U.. V.. XH.. Z..` (integers). `reset` restarts the loop from its
 * initial state; any other line is answered `error ...` and skipped. Every answer is flushed at once, as the float
 * loop's main.c does, so that a program can drive it line by line through pipes (`gainlink firmware run`).
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
    }
    return 0;
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
    printf("\n");
    fflush(stdout);
}

int main(void)
{
    static gl_fixed_loop_t loop;
    char line[4096]; /* as main.c's */
    float vals[GL_FX_P + GL_FX_QA];
    float u[GL_FX_M];
    gl_fixed_record_t rec;
    (void)gl_fixed_init(&loop, &gl_fixed_gains_default);
    printf("gainlink-fixed %s sha256:%s\n", GL_FX_NAME, GL_FX_ARTIFACT_SHA256);
    fflush(stdout);
    while (fgets(line, sizeof line, stdin) != NULL) {
        if (strncmp(line, "reset", 5) == 0) {
            gl_fixed_reset(&loop);
            continue;
        }
        if (parse(line, vals, GL_FX_P + GL_FX_Q) != 0) {
            printf("error unreadable line\n");
            fflush(stdout);
            continue;
        }
        (void)gl_fixed_step(&loop, vals, &vals[GL_FX_P], u);
        gl_fixed_record(&loop, u, &rec);
        print_record(&rec);
    }
    return 0;
}
