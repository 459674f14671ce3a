/*
 * imu_restore_app.c -- NAME_restore of an IMU module with a physics channel on the Cortex-M4 under
 * QEMU (not part of the flight module). Bound to one module as the other harnesses are
 * (tdc_module.h: -DBIND_NAME=name -DBIND_UNAME=NAME -DBIND_HEADER="name.h").
 *
 * Usage: imu_restore_app.elf VECTORS OUTPUTS STATE CUT MODE
 * VECTORS: little-endian int32 records of NAME_CHANNELS raw values then NAME_SENSORS temperatures.
 * The module starts with NAME_init on its built-in calibration and steps the records before CUT;
 * then its whole state is copied byte for byte into a buffer (the non-volatile memory), the copy is
 * changed as MODE says, and NAME_restore reads it into another state (filled with 0x5A: never
 * initialised) under a copy of the calibration at another address (the caller's RAM); that state
 * steps the records from CUT on. MODE: 0 the copy as it is; 1 one bit of restore_id flipped; 2 the
 * first physics channel's temp_prev at INT32_MAX (beyond every clip range, the id intact); 3 every
 * byte 0xFF (an erased flash page). OUTPUTS: NAME_CHANNELS int32 per record. STATE: the final
 * flags[NAME_CHANNELS] then samples (uint32).
 *
 * Then the cost of NAME_init and NAME_restore, for bench/bench_imu_restore_m4.py (meaningful under
 * `-icount shift=0`: 1 ns of virtual time per instruction, SysTick at 25 MHz counts one tick per
 * 40 instructions, checked by a calibration loop of known length, as bench_app.c): REPEATS calls of
 * each, timed as a loop, and the same loop with an empty function of the same signature; the
 * difference is the calls' cost (call and return included). Restores of the unchanged copy (kept,
 * returns 1) and of the copy with restore_id's bit flipped (refused, returns 0: the calibration's id
 * and then NAME_init).
 *
 * stdout (integers only): "restore <0|1>", "state_bytes <n>", "records <n>", "calibration
 * <instructions> <ticks>", "cost init|restore|refused <calls> <ticks> <null ticks> <returned 1>".
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "semihost.h"
#include "tdc_module.h"

#define imu_calibration_t TDC_CAT(BIND_NAME, _calibration_t)
#define imu_builtin TDC_CAT(BIND_NAME, _builtin)
#define imu_restore TDC_CAT(BIND_NAME, _restore)
#define IMU_CHANNELS TDC_CAT(BIND_UNAME, _CHANNELS)
#define IMU_SENSORS TDC_CAT(BIND_UNAME, _SENSORS)
#define IMU_PHYSICS_CHANNELS TDC_CAT(BIND_UNAME, _PHYSICS_CHANNELS) /* a module without one fails here */

#define CHUNK 256u
#define REPEATS 64u
#define CALIBRATION_LOOPS 100000u
#define MODE_KEEP 0
#define MODE_ID 1
#define MODE_BOUND 2
#define MODE_ERASED 3

#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)
#define SYST_MASK 0x00FFFFFFu

typedef char imu_restore_app_needs_a_physics_channel[IMU_PHYSICS_CHANNELS > 0u ? 1 : -1];

static int32_t records[(IMU_CHANNELS + IMU_SENSORS) * CHUNK];
static int32_t outputs[IMU_CHANNELS * CHUNK];
static imu_calibration_t cal_copy; /* the calibration at another address than the built-in one */
static tdc_state_t first;         /* from NAME_init: the run before the cut */
static tdc_state_t resumed;       /* from NAME_restore: the run from the cut */
static tdc_state_t saved;         /* what the non-volatile memory gives back */
static tdc_state_t kept;          /* the unchanged copy (timing) */
static tdc_state_t refused;       /* the copy with restore_id's bit flipped (timing) */
static tdc_state_t scratch;
static unsigned char nv[sizeof(tdc_state_t)];

typedef void (*init_fn)(tdc_state_t *, const imu_calibration_t *);
typedef int (*restore_fn)(tdc_state_t *, const imu_calibration_t *, const tdc_state_t *);

/* Same signatures as NAME_init and NAME_restore and, like them, not inlined. */
__attribute__((noinline)) static void null_init(tdc_state_t *s, const imu_calibration_t *c)
{
    __asm__ volatile("" : : "r"(s), "r"(c) : "memory");
}

__attribute__((noinline)) static int null_restore(tdc_state_t *s, const imu_calibration_t *c, const tdc_state_t *v)
{
    __asm__ volatile("" : : "r"(s), "r"(c), "r"(v) : "memory");
    return 0;
}

static uint32_t ticks_since(uint32_t start)
{
    return (start - SYST_CVR) & SYST_MASK; /* SysTick counts down */
}

/* A loop of known length: 2 instructions per iteration (subs, bne) plus 2. */
static uint32_t calibrate(void)
{
    uint32_t n = CALIBRATION_LOOPS;
    uint32_t t0 = SYST_CVR;
    __asm__ volatile("1: subs %0, %0, #1\n\tbne 1b" : "+r"(n) : : "cc");
    return ticks_since(t0);
}

static uint32_t time_init(init_fn f)
{
    uint32_t t0 = SYST_CVR;
    uint32_t i;
    for (i = 0u; i < REPEATS; ++i) {
        f(&scratch, &cal_copy);
    }
    return ticks_since(t0);
}

static uint32_t time_restore(restore_fn f, const tdc_state_t *copy, uint32_t *kept_count)
{
    uint32_t t0 = SYST_CVR;
    uint32_t i;
    uint32_t ones = 0u;
    for (i = 0u; i < REPEATS; ++i) {
        ones += (uint32_t)f(&scratch, &cal_copy, copy);
    }
    *kept_count = ones;
    return ticks_since(t0);
}

static int fail(const char *what, const char *path)
{
    printf("error: %s %s\n", what, path);
    return 1;
}

/* The power cycle at the cut: the state to non-volatile memory and back, changed as mode says. */
static int save_and_restore(long mode)
{
    memcpy(nv, &first, sizeof first); /* between two steps: the whole struct, byte for byte */
    memcpy(&saved, nv, sizeof saved);
    if (mode == MODE_ID) {
        saved.restore_id ^= 1u;
    } else if (mode == MODE_BOUND) {
        saved.physics[0].temp_prev = INT32_MAX;
    } else if (mode == MODE_ERASED) {
        memset(&saved, 0xFF, sizeof saved);
    }
    memcpy(&cal_copy, imu_builtin(), sizeof cal_copy);
    memset(&resumed, 0x5A, sizeof resumed); /* never initialised */
    return imu_restore(&resumed, &cal_copy, &saved);
}

int main(void)
{
    static char cmdline[512];
    char *argv[7];
    int argc = semihost_args(cmdline, sizeof cmdline, argv, 6);
    const size_t width = IMU_CHANNELS + IMU_SENSORS;
    tdc_state_t *state = &first;
    unsigned long index = 0u;
    unsigned long cut;
    long mode;
    int status = -1;
    FILE *in;
    FILE *out;
    FILE *st;
    size_t n;
    uint32_t ticks;
    uint32_t null_ticks;
    uint32_t ones;
    uint32_t unused;
    if (argc < 6) {
        printf("usage: imu_restore_app.elf VECTORS OUTPUTS STATE CUT MODE\n");
        return 2;
    }
    cut = strtoul(argv[4], NULL, 10);
    mode = strtol(argv[5], NULL, 10);
    in = fopen(argv[1], "rb");
    if (in == NULL) {
        return fail("cannot open", argv[1]);
    }
    out = fopen(argv[2], "wb");
    if (out == NULL) {
        return fail("cannot create", argv[2]);
    }
    tdc_init(&first, imu_builtin());
    while ((n = fread(records, width * sizeof records[0], CHUNK, in)) > 0u) {
        size_t k;
        for (k = 0u; k < n; ++k, ++index) {
            if (index == cut) {
                status = save_and_restore(mode);
                state = &resumed;
            }
            tdc_step(state, &records[k * width], &records[k * width + IMU_CHANNELS], &outputs[k * IMU_CHANNELS]);
        }
        if (fwrite(outputs, IMU_CHANNELS * sizeof outputs[0], n, out) != n) {
            return fail("cannot write", argv[2]);
        }
    }
    fclose(in);
    if (fclose(out) != 0) {
        return fail("cannot write", argv[2]);
    }
    st = fopen(argv[3], "wb");
    if (st == NULL || fwrite(state->flags, sizeof state->flags, 1u, st) != 1u ||
        fwrite(&state->samples, sizeof state->samples, 1u, st) != 1u || fclose(st) != 0) {
        return fail("cannot write", argv[3]);
    }
    printf("restore %d\n", status);
    printf("state_bytes %lu\n", (unsigned long)sizeof(tdc_state_t));
    printf("records %lu\n", index);

    /* the cost of NAME_init and NAME_restore (under -icount shift=0) */
    memcpy(&cal_copy, imu_builtin(), sizeof cal_copy);
    memcpy(&kept, nv, sizeof kept);
    memcpy(&refused, nv, sizeof refused);
    refused.restore_id ^= 1u;
    SYST_CSR = 0u;
    SYST_RVR = SYST_MASK;
    SYST_CVR = 0u;
    SYST_CSR = 5u; /* enable, processor clock, no interrupt */
    printf("calibration %lu %lu\n", (unsigned long)(2u * CALIBRATION_LOOPS + 2u), (unsigned long)calibrate());
    ticks = time_init(tdc_init);
    null_ticks = time_init(null_init);
    printf("cost init %lu %lu %lu 0\n", (unsigned long)REPEATS, (unsigned long)ticks, (unsigned long)null_ticks);
    ticks = time_restore(imu_restore, &kept, &ones);
    null_ticks = time_restore(null_restore, &kept, &unused);
    printf("cost restore %lu %lu %lu %lu\n", (unsigned long)REPEATS, (unsigned long)ticks,
        (unsigned long)null_ticks, (unsigned long)ones);
    ticks = time_restore(imu_restore, &refused, &ones);
    null_ticks = time_restore(null_restore, &refused, &unused);
    printf("cost refused %lu %lu %lu %lu\n", (unsigned long)REPEATS, (unsigned long)ticks,
        (unsigned long)null_ticks, (unsigned long)ones);
    return 0;
}
