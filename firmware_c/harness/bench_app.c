/*
 * bench_app.c -- instruction counts of the generated module on the Cortex-M4 build under QEMU
 * (not part of the flight module). Run with `-icount shift=0`: QEMU's virtual clock then advances
 * by exactly 1 ns per executed instruction, and SysTick (clocked from the 25 MHz system clock on
 * mps2-an386) counts one tick per 40 instructions. A calibration loop of known length checks that
 * ratio; the Python side (bench/bench_cortex_m.py) converts ticks to instructions.
 *
 * Usage: bench_app.elf [VECTORS]
 * VECTORS: int32 records (accel_q4ug, temp_mdegc, command) as for test_app; the first MAX_SAMPLES
 * are loaded into RAM before anything is timed. Without it a synthetic 0.1 degC/s ramp across the
 * model's valid range is used. Every timed loop is run a second time with an empty function of the
 * same signature in place of NAME_step; the difference is the cost of the calls themselves
 * (NAME_step including its call and return, not the loop or the timer reads).
 *
 * Streaming models (TDC_DECIMATION > 0, from the Makefile): the network steps on the first sample
 * of every period of D samples (or, spread schedule, on all of them). Every sample is timed alone;
 * the ticks are also summed per phase of the period, whose average over the periods is the cost of
 * that phase to well under one instruction (a spread schedule's worst sample). Memoryless models (TDC_DECIMATION == 0): the stream is timed in batches
 * of BATCH samples; the most expensive batch bounds the worst case (PLA's interval search grows
 * with temperature).
 *
 * Output lines (integers only): "calibration <instructions> <ticks>", "model_id <id>",
 * "decimation <D>", "samples <n>", "network <count> <ticks> <null ticks> <max ticks>",
 * "plain <count> <ticks> <null ticks>", "phase <p> <ticks> <null ticks>" (one line per phase), "batch <count> <ticks> <null ticks>" (memoryless, one line
 * per batch), "sink <value>".
 */
#include <stdio.h>

#include "semihost.h"
#include "tdc_module.h"

#ifndef TDC_DECIMATION
#define TDC_DECIMATION 0
#endif
/* The rate the timed stream stands for (the Makefile's RATE_MILLIHZ, default 200 Hz): a module built
 * for another rate does not compile (NAME_CHECK_SAMPLE_RATE_MILLIHZ, the generated rate contract). */
#ifndef TDC_RATE_MILLIHZ
#define TDC_RATE_MILLIHZ 200000u
#endif
TDC_CHECK_SAMPLE_RATE_MILLIHZ(TDC_RATE_MILLIHZ);
#define MAX_SAMPLES 60000u
#define BATCH 250u
#define CALIBRATION_LOOPS 1000000u

#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)
#define SYST_MASK 0x00FFFFFFu

static int32_t accel[MAX_SAMPLES];
static int32_t temp[MAX_SAMPLES];
static volatile int32_t sink;
static tdc_state_t state;

typedef int32_t (*step_fn)(tdc_state_t *, int32_t, int32_t);

/* Same signature as NAME_step and, like it, in another function that cannot be inlined. */
__attribute__((noinline)) static int32_t null_step(tdc_state_t *s, int32_t a, int32_t t)
{
    __asm__ volatile("" : : "r"(s), "r"(a), "r"(t) : "memory");
    return a;
}

static uint32_t ticks_since(uint32_t start)
{
    return (start - SYST_CVR) & SYST_MASK; /* SysTick counts down */
}

static void start_systick(void)
{
    SYST_CSR = 0u;
    SYST_RVR = SYST_MASK;
    SYST_CVR = 0u;
    SYST_CSR = 5u; /* enable, processor clock, no interrupt */
}

/* A loop of known length: 2 instructions per iteration (subs, bne) plus 2. */
static uint32_t calibrate(void)
{
    uint32_t n = CALIBRATION_LOOPS;
    uint32_t t0 = SYST_CVR;
    __asm__ volatile("1: subs %0, %0, #1\n\tbne 1b" : "+r"(n) : : "cc");
    return ticks_since(t0);
}

static size_t load(const char *path)
{
    static int32_t records[3u * 256u];
    FILE *in = fopen(path, "rb");
    size_t n = 0u;
    size_t got;
    if (in == NULL) {
        printf("error: cannot open %s\n", path);
        return 0u;
    }
    while (n < MAX_SAMPLES && (got = fread(records, 3u * sizeof records[0], 256u, in)) > 0u) {
        size_t k;
        for (k = 0u; k < got && n < MAX_SAMPLES; ++k, ++n) {
            accel[n] = records[3u * k];
            temp[n] = records[3u * k + 1u];
        }
    }
    fclose(in);
    return n;
}

static size_t synthesise(void)
{
    /* 0.1 degC per second at 200 Hz = 0.5 mdegC per sample, centred in the valid range; drift of
     * about 0.1 mg per degC around 1 g plus +-2 mg of noise (LCG), in 1/16 ug */
    const int32_t lo = TDC_VALID_TEMP_MIN_MDEGC > -40000 ? TDC_VALID_TEMP_MIN_MDEGC : -40000;
    const int32_t hi = TDC_VALID_TEMP_MAX_MDEGC < 85000 ? TDC_VALID_TEMP_MAX_MDEGC : 85000;
    uint32_t seed = 12345u;
    size_t n;
    for (n = 0u; n < MAX_SAMPLES; ++n) {
        int32_t t = lo + (int32_t)((uint32_t)(hi - lo) / MAX_SAMPLES * (uint32_t)n);
        seed = seed * 1664525u + 1013904223u;
        temp[n] = t;
        accel[n] = 16000000 + (t - 20000) * 1600 / 1000 + ((int32_t)(seed >> 20) - 2048) * 16;
    }
    return MAX_SAMPLES;
}

#if TDC_DECIMATION > 0
struct stream_ticks {
    uint32_t network;
    uint32_t network_max;
    uint32_t plain;
};

/* ticks summed per phase of the period over the stream (a spread schedule's worst phase) */
static uint32_t phase_ticks[2][TDC_DECIMATION];

/* Periods of D samples from the start of a stream (the network steps on sample 0 of each); every
 * sample is timed alone, and its ticks are added to its phase's sum in phase_ticks[which]. */
static struct stream_ticks time_stream(step_fn step, size_t periods, int which)
{
    struct stream_ticks r = { 0u, 0u, 0u };
    size_t p;
    size_t i = 0u;
    tdc_init(&state);
    for (p = 0u; p < periods; ++p) {
        size_t j;
        for (j = 0u; j < (size_t)TDC_DECIMATION; ++j, ++i) {
            uint32_t t0 = SYST_CVR;
            uint32_t dt;
            sink = step(&state, accel[i], temp[i]);
            dt = ticks_since(t0);
            phase_ticks[which][j] += dt;
            if (j == 0u) {
                r.network += dt;
                r.network_max = dt > r.network_max ? dt : r.network_max;
            } else {
                r.plain += dt;
            }
        }
    }
    return r;
}
#else
static uint32_t time_batch(step_fn step, size_t start)
{
    uint32_t t0 = SYST_CVR;
    size_t i;
    for (i = start; i < start + BATCH; ++i) {
        sink = step(&state, accel[i], temp[i]);
    }
    return ticks_since(t0);
}
#endif

int main(void)
{
    static char cmdline[512];
    char *argv[3];
    int argc = semihost_args(cmdline, sizeof cmdline, argv, 2);
    size_t n = argc > 1 ? load(argv[1]) : synthesise();
    if (n == 0u) {
        return 1;
    }
    start_systick();
    printf("calibration %lu %lu\n", (unsigned long)(2u * CALIBRATION_LOOPS + 2u), (unsigned long)calibrate());
    printf("model_id %s\n", tdc_model_id());
    printf("decimation %u\n", (unsigned)TDC_DECIMATION);
#if TDC_DECIMATION > 0
    {
        size_t periods = n / (size_t)TDC_DECIMATION;
        struct stream_ticks real = time_stream(tdc_step, periods, 0);
        struct stream_ticks null = time_stream(null_step, periods, 1);
        size_t j;
        printf("samples %lu\n", (unsigned long)(periods * (size_t)TDC_DECIMATION));
        printf("network %lu %lu %lu %lu\n", (unsigned long)periods, (unsigned long)real.network,
            (unsigned long)null.network, (unsigned long)real.network_max);
        printf("plain %lu %lu %lu\n", (unsigned long)(periods * ((size_t)TDC_DECIMATION - 1u)),
            (unsigned long)real.plain, (unsigned long)null.plain);
        for (j = 0u; j < (size_t)TDC_DECIMATION; ++j) {
            printf("phase %lu %lu %lu\n", (unsigned long)j, (unsigned long)phase_ticks[0][j],
                (unsigned long)phase_ticks[1][j]);
        }
    }
#else
    {
        size_t start;
        printf("samples %lu\n", (unsigned long)(n / BATCH * BATCH));
        tdc_init(&state);
        for (start = 0u; start + BATCH <= n; start += BATCH) {
            uint32_t real = time_batch(tdc_step, start);
            uint32_t null = time_batch(null_step, start);
            printf("batch %u %lu %lu\n", (unsigned)BATCH, (unsigned long)real, (unsigned long)null);
        }
    }
#endif
    printf("sink %ld\n", (long)sink);
    return 0;
}
