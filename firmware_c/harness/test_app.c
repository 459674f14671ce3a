/*
 * test_app.c -- bit-exactness harness for the Cortex-M4 build (not part of the flight module).
 *
 * Usage under QEMU (semihosting, files on the host):
 *   test_app.elf VECTORS OUTPUTS [STATES]
 * VECTORS holds little-endian int32 records (accel_q4ug, temp_mdegc, command), the format of
 * codegen.hostbuild.write_vectors. command bits 0-1: 0 = sample, 1 = NAME_reset before it,
 * 2 = NAME_init before it; bit 4 selects the instance (state A or B), so that two instances can be
 * interleaved sample by sample. Every record gives one int32 output in OUTPUTS, in record order.
 * Runs of plain samples of one instance go through NAME_run (one call per run within a chunk),
 * single samples through NAME_step, so both entry points are exercised. STATES receives the two
 * final state structs (A, B) byte for byte. stdout gets "model_id", "state_bytes", "records".
 */
#include <stdio.h>

#include "semihost.h"
#include "tdc_module.h"

#define CHUNK 1024u
#define CMD_OP_MASK 3
#define CMD_RESET 1
#define CMD_INIT 2
#define CMD_INSTANCE_B 16

static int32_t records[3u * CHUNK];
static int32_t accel[CHUNK];
static int32_t temp[CHUNK];
static int32_t command[CHUNK];
static int32_t outputs[CHUNK];
static tdc_state_t states[2];

static int fail(const char *what, const char *path)
{
    printf("error: %s %s\n", what, path);
    return 1;
}

/* Process n records: apply each command, then stream maximal runs of plain samples. */
static void process(size_t n)
{
    size_t k = 0u;
    while (k < n) {
        int32_t cmd = command[k];
        tdc_state_t *state = &states[(cmd & CMD_INSTANCE_B) != 0 ? 1 : 0];
        int32_t plain = cmd & CMD_INSTANCE_B; /* the same instance, no reset/init */
        size_t end = k + 1u;
        if ((cmd & CMD_OP_MASK) == CMD_RESET) {
            tdc_reset(state);
        } else if ((cmd & CMD_OP_MASK) == CMD_INIT) {
            tdc_init(state);
        }
        while (end < n && command[end] == plain) {
            ++end;
        }
        if (end - k == 1u) {
            outputs[k] = tdc_step(state, accel[k], temp[k]);
        } else {
            tdc_run(state, &accel[k], &temp[k], &outputs[k], end - k);
        }
        k = end;
    }
}

int main(void)
{
    static char cmdline[512];
    char *argv[5];
    int argc = semihost_args(cmdline, sizeof cmdline, argv, 4);
    FILE *in;
    FILE *out;
    unsigned long total = 0u;
    size_t n;
    if (argc < 3) {
        printf("usage: test_app.elf VECTORS OUTPUTS [STATES]\n");
        return 2;
    }
    in = fopen(argv[1], "rb");
    if (in == NULL) {
        return fail("cannot open", argv[1]);
    }
    out = fopen(argv[2], "wb");
    if (out == NULL) {
        return fail("cannot create", argv[2]);
    }
    printf("model_id %s\n", tdc_model_id());
    printf("state_bytes %u\n", (unsigned)sizeof(tdc_state_t));
    tdc_init(&states[0]);
    tdc_init(&states[1]);
    while ((n = fread(records, 3u * sizeof records[0], CHUNK, in)) > 0u) {
        size_t k;
        for (k = 0u; k < n; ++k) {
            accel[k] = records[3u * k];
            temp[k] = records[3u * k + 1u];
            command[k] = records[3u * k + 2u];
        }
        process(n);
        if (fwrite(outputs, sizeof outputs[0], n, out) != n) {
            return fail("cannot write", argv[2]);
        }
        total += (unsigned long)n;
    }
    fclose(in);
    if (fclose(out) != 0) {
        return fail("cannot write", argv[2]);
    }
    if (argc > 3) {
        FILE *st = fopen(argv[3], "wb");
        if (st == NULL || fwrite(states, sizeof states, 1u, st) != 1u || fclose(st) != 0) {
            return fail("cannot write", argv[3]);
        }
    }
    printf("records %lu\n", total);
    return 0;
}
