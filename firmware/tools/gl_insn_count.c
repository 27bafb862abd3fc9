/**
 * @file gl_insn_count.c
 * @brief QEMU TCG plugin: count the guest instructions of each call of one function, callees included.
 *
 * Debian's QEMU is built with plugin support but ships no qemu-plugin.h, so the few API v1
 * declarations used here are written out below (they match QEMU 7.2's include/qemu/qemu-plugin.h).
 *
 * Every executed instruction increments one inline counter. A call opens at the function's entry
 * (`entry=ADDR`) and closes at one of its return addresses (`ret=ADDR`, the instruction after each call
 * site, up to 256); what the counter advanced in between is that call's cost: the function's own code
 * and everything it calls (soft-float and libgcc routines, gl_fmaf, memcpy), which lie outside its
 * symbol. Instructions inside [lo, hi) (`lo=ADDR hi=ADDR`, optional: the function's own symbol) are also
 * counted apart, so a report can show how much of the cost is the callees'. Interrupt handlers that ran
 * during a call would be counted too: the image masks interrupts around the calls it measures.
 * At exit `insns=N calls=M own=K min=A max=B` (N summed over the M calls, A and B the cheapest and the
 * dearest call) is written to `out=PATH`; with `each=PATH`, every call's count is written there as it closes, one
 * a line in call order (what a bound per path is checked against). Counting is exact and deterministic.
 * Build: cc -shared -fPIC -O2 -o libgl_insn_count.so gl_insn_count.c
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
typedef void (*qemu_plugin_vcpu_udata_cb_t)(unsigned int vcpu_index, void *userdata);
enum qemu_plugin_cb_flags { QEMU_PLUGIN_CB_NO_REGS, QEMU_PLUGIN_CB_R_REGS, QEMU_PLUGIN_CB_RW_REGS };
void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, qemu_plugin_vcpu_tb_trans_cb_t cb);
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
struct qemu_plugin_insn *qemu_plugin_tb_get_insn(const struct qemu_plugin_tb *tb, size_t idx);
uint64_t qemu_plugin_insn_vaddr(const struct qemu_plugin_insn *insn);
void qemu_plugin_register_vcpu_insn_exec_inline(struct qemu_plugin_insn *insn, enum qemu_plugin_op op, void *ptr,
                                                uint64_t imm);
void qemu_plugin_register_vcpu_insn_exec_cb(struct qemu_plugin_insn *insn, qemu_plugin_vcpu_udata_cb_t cb,
                                            enum qemu_plugin_cb_flags flags, void *userdata);
void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, qemu_plugin_udata_cb_t cb, void *userdata);
__attribute__((visibility("default"))) int qemu_plugin_version = 1;
__attribute__((visibility("default"))) int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info,
                                                               int argc, char **argv);
/* ---- end of API declarations ---- */

#define MAX_RETURNS 256

static uint64_t range_lo, range_hi, entry_addr;
static uint64_t return_addrs[MAX_RETURNS];
static int n_returns;
static uint64_t executed;   /* every instruction (inline) */
static uint64_t own_count;  /* instructions inside [lo, hi) (inline) */
static uint64_t call_start; /* `executed` when the open call began */
static int in_call;
static uint64_t insn_count, call_count, min_call = UINT64_MAX, max_call;
static char out_path[1024];
static FILE *each_file; /* every call's count, one a line (each=PATH), or NULL */

static void on_entry(unsigned int vcpu, void *userdata)
{
    (void)vcpu;
    (void)userdata;
    call_start = executed;
    in_call = 1;
}

static void on_return(unsigned int vcpu, void *userdata)
{
    (void)vcpu;
    (void)userdata;
    if (!in_call) {
        return; /* reached by another path than the function's return */
    }
    in_call = 0;
    uint64_t cost = executed - call_start;
    insn_count += cost;
    call_count++;
    min_call = cost < min_call ? cost : min_call;
    max_call = cost > max_call ? cost : max_call;
    if (each_file != NULL) {
        fprintf(each_file, "%" PRIu64 "\n", cost);
    }
}

static int is_return_addr(uint64_t pc)
{
    for (int i = 0; i < n_returns; ++i) {
        if (return_addrs[i] == pc) {
            return 1;
        }
    }
    return 0;
}

/* The entry and the return callbacks are registered after the inline increment of their own instruction,
 * so whichever order QEMU runs the two in, both see the counter in the same state relative to their
 * instruction, and the difference is the call's instructions exactly. */
static void on_translate(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    (void)id;
    size_t n = qemu_plugin_tb_n_insns(tb);
    for (size_t i = 0; i < n; ++i) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t pc = qemu_plugin_insn_vaddr(insn);
        qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64, &executed, 1);
        if (pc >= range_lo && pc < range_hi) {
            qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64, &own_count, 1);
        }
        if (pc == entry_addr) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_entry, QEMU_PLUGIN_CB_NO_REGS, NULL);
        }
        if (is_return_addr(pc)) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_return, QEMU_PLUGIN_CB_NO_REGS, NULL);
        }
    }
}

static void on_plugin_exit(qemu_plugin_id_t id, void *userdata)
{
    (void)id;
    (void)userdata;
    if (each_file != NULL) {
        fclose(each_file);
        each_file = NULL;
    }
    FILE *f = fopen(out_path, "w");
    if (f != NULL) {
        fprintf(f, "insns=%" PRIu64 " calls=%" PRIu64 " own=%" PRIu64 " min=%" PRIu64 " max=%" PRIu64 "\n",
                insn_count, call_count, own_count, call_count ? min_call : 0u, max_call);
        fclose(f);
    }
}

int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc, char **argv)
{
    (void)info;
    bool have_out = false, have_entry = false;
    for (int i = 0; i < argc; ++i) {
        const char *a = argv[i];
        if (strncmp(a, "lo=", 3) == 0) {
            range_lo = strtoull(a + 3, NULL, 0);
        } else if (strncmp(a, "hi=", 3) == 0) {
            range_hi = strtoull(a + 3, NULL, 0);
        } else if (strncmp(a, "entry=", 6) == 0) {
            entry_addr = strtoull(a + 6, NULL, 0);
            have_entry = true;
        } else if (strncmp(a, "ret=", 4) == 0 && n_returns < MAX_RETURNS) {
            return_addrs[n_returns++] = strtoull(a + 4, NULL, 0);
        } else if (strncmp(a, "each=", 5) == 0) {
            each_file = fopen(a + 5, "w");
            if (each_file == NULL) {
                fprintf(stderr, "gl_insn_count: cannot write %s\n", a + 5);
                return -1;
            }
        } else if (strncmp(a, "out=", 4) == 0) {
            snprintf(out_path, sizeof out_path, "%s", a + 4);
            have_out = true;
        } else {
            fprintf(stderr, "gl_insn_count: unknown or surplus argument %s\n", a);
            return -1;
        }
    }
    if (!have_out || !have_entry || n_returns == 0 || range_hi < range_lo) {
        fprintf(stderr, "gl_insn_count: needs entry=, at least one ret=, out= (and lo= <= hi= when given)\n");
        return -1;
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_translate);
    qemu_plugin_register_atexit_cb(id, on_plugin_exit, NULL);
    return 0;
}
