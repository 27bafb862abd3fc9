/**
 * @file gl_insn_count.c
 * @brief QEMU TCG plugin: count guest instructions executed inside one address range.
 *
 * Debian's QEMU is built with plugin support but ships no qemu-plugin.h, so the few API v1
 * declarations used here are written out below (they match QEMU 7.2's include/qemu/qemu-plugin.h).
 *
 * Arguments: lo=ADDR hi=ADDR (the range, [lo, hi)), entry=ADDR (its entry point, counted as calls),
 * out=PATH (where `insns=N calls=M` is written at exit). Counting is inline (no callbacks), exact
 * and deterministic. Build: cc -shared -fPIC -O2 -o libgl_insn_count.so gl_insn_count.c
 */
#include <inttypes.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- QEMU plugin API v1 (subset) ---- */
typedef uint64_t qemu_plugin_id_t;
typedef struct qemu_info_t {
    const char *target_name;
    struct {
        int min;
        int cur;
    } version;
    bool system_emulation;
    union {
        struct {
            int smp_vcpus;
            int max_vcpus;
        } system;
    };
} qemu_info_t;
struct qemu_plugin_tb;
struct qemu_plugin_insn;
enum qemu_plugin_op { QEMU_PLUGIN_INLINE_ADD_U64 };
typedef void (*qemu_plugin_vcpu_tb_trans_cb_t)(qemu_plugin_id_t id, struct qemu_plugin_tb *tb);
typedef void (*qemu_plugin_udata_cb_t)(qemu_plugin_id_t id, void *userdata);
void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, qemu_plugin_vcpu_tb_trans_cb_t cb);
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
struct qemu_plugin_insn *qemu_plugin_tb_get_insn(const struct qemu_plugin_tb *tb, size_t idx);
uint64_t qemu_plugin_insn_vaddr(const struct qemu_plugin_insn *insn);
void qemu_plugin_register_vcpu_insn_exec_inline(struct qemu_plugin_insn *insn, enum qemu_plugin_op op, void *ptr,
                                                uint64_t imm);
void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, qemu_plugin_udata_cb_t cb, void *userdata);
__attribute__((visibility("default"))) int qemu_plugin_version = 1;
__attribute__((visibility("default"))) int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info,
                                                               int argc, char **argv);
/* ---- end of API declarations ---- */

static uint64_t range_lo, range_hi, entry_addr;
static uint64_t insn_count, call_count;
static char out_path[1024];

static void on_translate(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    (void)id;
    size_t n = qemu_plugin_tb_n_insns(tb);
    for (size_t i = 0; i < n; ++i) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t pc = qemu_plugin_insn_vaddr(insn);
        if (pc >= range_lo && pc < range_hi) {
            qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64, &insn_count, 1);
        }
        if (pc == entry_addr) {
            qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64, &call_count, 1);
        }
    }
}

static void on_plugin_exit(qemu_plugin_id_t id, void *userdata)
{
    (void)id;
    (void)userdata;
    FILE *f = fopen(out_path, "w");
    if (f != NULL) {
        fprintf(f, "insns=%" PRIu64 " calls=%" PRIu64 "\n", insn_count, call_count);
        fclose(f);
    }
}

int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc, char **argv)
{
    (void)info;
    bool have_out = false;
    for (int i = 0; i < argc; ++i) {
        const char *a = argv[i];
        if (strncmp(a, "lo=", 3) == 0) {
            range_lo = strtoull(a + 3, NULL, 0);
        } else if (strncmp(a, "hi=", 3) == 0) {
            range_hi = strtoull(a + 3, NULL, 0);
        } else if (strncmp(a, "entry=", 6) == 0) {
            entry_addr = strtoull(a + 6, NULL, 0);
        } else if (strncmp(a, "out=", 4) == 0) {
            snprintf(out_path, sizeof out_path, "%s", a + 4);
            have_out = true;
        } else {
            fprintf(stderr, "gl_insn_count: unknown argument %s\n", a);
            return -1;
        }
    }
    if (!have_out || range_hi <= range_lo) {
        fprintf(stderr, "gl_insn_count: needs lo=, hi= (hi > lo) and out=\n");
        return -1;
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_translate);
    qemu_plugin_register_atexit_cb(id, on_plugin_exit, NULL);
    return 0;
}
