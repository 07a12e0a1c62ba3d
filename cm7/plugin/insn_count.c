/*
 * QEMU TCG plugin: counts the guest instructions executed in each measurement window,
 * from the entry of `bench_start` to the entry of `bench_end`, and prints one line
 * per window: "insn_count: window <n> <instructions>". Used by `cargo xtask test`
 * (see cm7/README-cm7.md); the two addresses come from the ELF's symbol table:
 *
 *   -plugin insn_count.so,start=0x<bench_start>,end=0x<bench_end> -d plugin
 *
 * (`-d plugin` is needed: qemu_plugin_outs writes to QEMU's log, i.e. stderr.)
 *
 * With the extra argument `profile=on` it also attributes each window's instructions
 * to their addresses: after the window line it prints one line per executed address,
 * "insn_pc: window <n> 0x<pc> <instructions>", in no particular order. The per-address
 * counts of a window add up to its total (`cargo xtask profile` checks that), since
 * both counters are bumped by the same instrumentation point of every instruction.
 *
 * Debian ships QEMU 7.2 without qemu-plugin.h, so the few declarations used are
 * written out below from the plugin API (version 1) as QEMU 7.2 documents it.
 */
#include <inttypes.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- QEMU 7.2 plugin API, version 1: only what this plugin uses ---- */
typedef uint64_t qemu_plugin_id_t;
typedef struct qemu_info_t qemu_info_t; /* only passed through by pointer */
struct qemu_plugin_tb;
struct qemu_plugin_insn;
enum qemu_plugin_cb_flags { QEMU_PLUGIN_CB_NO_REGS, QEMU_PLUGIN_CB_R_REGS, QEMU_PLUGIN_CB_RW_REGS };
enum qemu_plugin_op { QEMU_PLUGIN_INLINE_ADD_U64 };
typedef void (*qemu_plugin_vcpu_tb_trans_cb_t)(qemu_plugin_id_t id, struct qemu_plugin_tb *tb);
typedef void (*qemu_plugin_vcpu_udata_cb_t)(unsigned int vcpu_index, void *userdata);
typedef void (*qemu_plugin_udata_cb_t)(qemu_plugin_id_t id, void *userdata);
void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, qemu_plugin_vcpu_tb_trans_cb_t cb);
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
struct qemu_plugin_insn *qemu_plugin_tb_get_insn(const struct qemu_plugin_tb *tb, size_t idx);
uint64_t qemu_plugin_insn_vaddr(const struct qemu_plugin_insn *insn);
void qemu_plugin_register_vcpu_insn_exec_cb(struct qemu_plugin_insn *insn, qemu_plugin_vcpu_udata_cb_t cb,
                                            enum qemu_plugin_cb_flags flags, void *userdata);
void qemu_plugin_register_vcpu_insn_exec_inline(struct qemu_plugin_insn *insn, enum qemu_plugin_op op,
                                                void *ptr, uint64_t imm);
void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, qemu_plugin_udata_cb_t cb, void *userdata);
void qemu_plugin_outs(const char *string);
#define EXPORT __attribute__((visibility("default")))
EXPORT int qemu_plugin_version = 1;
/* ---- end of API declarations ---- */

static uint64_t start_pc, end_pc; /* even (Thumb bit cleared) */
static uint64_t executed;         /* every executed instruction, bumped inline */
static uint64_t window_began;     /* `executed` at the last bench_start entry */
static int in_window;
static unsigned windows;

/* Profile: one node per guest instruction address ever translated. Nodes are never
 * freed or moved, because QEMU keeps the address of `count` in the generated code. */
struct pc_node {
    uint64_t pc;
    uint64_t count; /* executions since the start of the run, bumped inline */
    uint64_t base;  /* `count` at the last bench_start entry */
    struct pc_node *next;
};
#define PC_BUCKETS 4096u
static struct pc_node *pc_table[PC_BUCKETS];
static int profile;

/* The node of `pc`, created on first sight; NULL only when out of memory. */
static struct pc_node *pc_node(uint64_t pc)
{
    struct pc_node **head = &pc_table[(pc >> 1) % PC_BUCKETS];
    for (struct pc_node *n = *head; n; n = n->next)
        if (n->pc == pc)
            return n;
    struct pc_node *n = calloc(1, sizeof *n);
    if (n) {
        n->pc = pc;
        n->next = *head;
        *head = n;
    }
    return n;
}

static void profile_start(void)
{
    for (unsigned b = 0; b < PC_BUCKETS; b++)
        for (struct pc_node *n = pc_table[b]; n; n = n->next)
            n->base = n->count;
}

static void profile_dump(unsigned window)
{
    char line[96];
    for (unsigned b = 0; b < PC_BUCKETS; b++)
        for (struct pc_node *n = pc_table[b]; n; n = n->next)
            if (n->count != n->base) {
                snprintf(line, sizeof line, "insn_pc: window %u 0x%" PRIx64 " %" PRIu64 "\n", window, n->pc,
                         n->count - n->base);
                qemu_plugin_outs(line);
            }
}

static void on_start(unsigned int vcpu, void *udata)
{
    (void)vcpu, (void)udata;
    window_began = executed;
    in_window = 1;
    if (profile)
        profile_start();
}

static void on_end(unsigned int vcpu, void *udata)
{
    char line[80];
    (void)vcpu, (void)udata;
    if (!in_window) {
        qemu_plugin_outs("insn_count: error: bench_end without bench_start\n");
        return;
    }
    snprintf(line, sizeof line, "insn_count: window %u %" PRIu64 "\n", windows, executed - window_began);
    qemu_plugin_outs(line);
    if (profile)
        profile_dump(windows);
    windows++;
    in_window = 0;
}

/* Instrumentation is attached once per translated block; QEMU reuses it every time
 * the block runs. The count is incremented before each instruction executes. */
static void on_translate(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    size_t n = qemu_plugin_tb_n_insns(tb);
    (void)id;
    for (size_t i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t pc = qemu_plugin_insn_vaddr(insn);
        if (pc == start_pc)
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_start, QEMU_PLUGIN_CB_NO_REGS, NULL);
        else if (pc == end_pc)
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_end, QEMU_PLUGIN_CB_NO_REGS, NULL);
        qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64, &executed, 1);
        if (profile) {
            struct pc_node *node = pc_node(pc);
            if (!node) {
                fprintf(stderr, "insn_count: out of memory for the profile\n");
                abort();
            }
            qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64, &node->count, 1);
        }
    }
}

static void on_qemu_exit(qemu_plugin_id_t id, void *udata)
{
    char line[96];
    (void)id, (void)udata;
    snprintf(line, sizeof line, "insn_count: %u windows, %" PRIu64 " instructions in all%s\n", windows,
             executed, in_window ? ", last window never ended" : "");
    qemu_plugin_outs(line);
}

EXPORT int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc, char **argv)
{
    (void)info;
    for (int i = 0; i < argc; i++) {
        if (strncmp(argv[i], "start=", 6) == 0)
            start_pc = strtoull(argv[i] + 6, NULL, 0) & ~1ull;
        else if (strncmp(argv[i], "end=", 4) == 0)
            end_pc = strtoull(argv[i] + 4, NULL, 0) & ~1ull;
        else if (strcmp(argv[i], "profile=on") == 0)
            profile = 1;
        else {
            fprintf(stderr, "insn_count: unknown argument `%s`\n", argv[i]);
            return -1;
        }
    }
    if (start_pc == 0 || end_pc == 0 || start_pc == end_pc) {
        fprintf(stderr, "insn_count: need distinct start=ADDR,end=ADDR arguments\n");
        return -1;
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_translate);
    qemu_plugin_register_atexit_cb(id, on_qemu_exit, NULL);
    return 0;
}
