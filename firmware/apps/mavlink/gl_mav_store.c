/**
 * @file gl_mav_store.c
 * @brief Save and load the committed gain set as `ID VALUE` text (see gl_mav_store.h).
 */
#define _POSIX_C_SOURCE 200809L
#include "gl_mav_store.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

int gl_mav_store_save(const gl_mav_params_t *table, const char *path)
{
    char tmp[4096];
    if (snprintf(tmp, sizeof tmp, "%s.tmp", path) >= (int)sizeof tmp) {
        return -1;
    }
    FILE *f = fopen(tmp, "w");
    if (f == NULL) {
        return -1;
    }
    int bad = fprintf(f, "# gainlink MAVLink parameters (committed gain set)\n") < 0;
    for (uint16_t k = 0; k < table->count && !bad; ++k) {
        const gl_mav_param_t *p = &table->param[k];
        if (p->header < 0) {
            bad = fprintf(f, "%s %.9g\n", p->id, (double)(&table->committed.Ts)[p->offset]) < 0;
        }
    }
    if (!bad) {
        bad = fprintf(f, "GL_HASH %lu\n", (unsigned long)table->committed.crc32) < 0;
    }
    bad |= fflush(f) != 0;
    bad |= fsync(fileno(f)) != 0;
    bad |= fclose(f) != 0;
    if (bad || rename(tmp, path) != 0) {
        remove(tmp);
        return -1;
    }
    return 0;
}

int gl_mav_store_load(gl_mav_params_t *table, const char *path, char *why, size_t why_len)
{
    FILE *f = fopen(path, "r");
    if (f == NULL) {
        snprintf(why, why_len, "%s", strerror(errno));
        return errno == ENOENT ? 1 : -1;
    }
    gl_gains_t candidate = table->committed;
    int have_hash = 0;
    char line[256];
    int line_no = 0;
    int rc = 0;
    while (rc == 0 && fgets(line, sizeof line, f) != NULL) {
        ++line_no;
        if (line[0] == '#' || line[0] == '\n') {
            continue;
        }
        char id[GL_MAV_ID_LEN + 1];
        char value[128];
        if (sscanf(line, "%16s %127s", id, value) != 2) {
            snprintf(why, why_len, "line %d: expected 'ID VALUE'", line_no);
            rc = -1;
            break;
        }
        char *end = NULL;
        if (strcmp(id, "GL_HASH") == 0) {
            unsigned long h = strtoul(value, &end, 10);
            candidate.crc32 = (uint32_t)h;
            have_hash = 1;
        } else {
            int32_t k = gl_mav_params_find(table, id);
            if (k < 0 || table->param[k].header >= 0) {
                snprintf(why, why_len, "line %d: unknown parameter %s", line_no, id);
                rc = -1;
                break;
            }
            (&candidate.Ts)[table->param[k].offset] = strtof(value, &end);
        }
        if (end == value || *end != '\0') {
            snprintf(why, why_len, "line %d: bad number %s", line_no, value);
            rc = -1;
        }
    }
    fclose(f);
    if (rc == 0 && !have_hash) {
        snprintf(why, why_len, "no GL_HASH line");
        rc = -1;
    }
    if (rc == 0) {
        gl_status_t st = gl_mav_params_replace(table, &candidate);
        if (st != GL_OK) {
            snprintf(why, why_len, "stored set refused by the loop's checks (status %d)", (int)st);
            rc = -1;
        }
    }
    return rc;
}
