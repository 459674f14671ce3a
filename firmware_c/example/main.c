/*
 * main.c -- demo driver of the GNC integration example (not flight code).
 *
 * Two minutes of a synthetic two-axis IMU at 200 Hz: the temperature climbs from 10 degC below the
 * primary model's valid maximum to 10 degC above it and back (out of range in the middle), a
 * telecommand switches to the alternative model at 60 s, an unknown model id is refused at 90 s,
 * and the primary model is selected again at 100 s. Every 10 s one line; at the end the health
 * counters and a checksum of every output. Host and Cortex-M4 builds print the same lines; the
 * target build adds "cpu" lines.
 *
 * On the Cortex-M4 build (QEMU mps2-an386) the sensor task is released by the SysTick interrupt
 * every 5 ms, as a data-ready interrupt or an RTOS tick would release it, and the core sleeps
 * (WFI) in between; the task's own cost is read from SysTick (1 tick = 40 instructions when QEMU
 * runs with -icount shift=0, which also lets the idle time pass instantly).
 */
#include <stdint.h>
#include <stdio.h>

#include "gnc_integration.h"
#include "tdc_models.h"

#define RATE_HZ 200u
#define DURATION_S 120u
#define N_SAMPLES (RATE_HZ * DURATION_S)
#define REPORT_EVERY (10u * RATE_HZ)

static const char unknown_model_id[] = "sha256:0000000000000000000000000000000000000000000000000000000000000000";

#if defined(__arm__) && defined(__ARM_ARCH_7EM__)
#define ON_TARGET 1
#define SYSCLK_HZ 25000000u
#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)
#define PERIOD_TICKS (SYSCLK_HZ / RATE_HZ)

static volatile uint32_t periods;

void SysTick_Handler(void);
void SysTick_Handler(void)
{
    periods += 1u; /* in a real system: the IMU's data-ready interrupt releases the sensor task */
}

static void start_200hz_tick(void)
{
    SYST_RVR = PERIOD_TICKS - 1u;
    SYST_CVR = 0u;
    SYST_CSR = 7u; /* enable, interrupt, processor clock */
}

static void wait_for_period(uint32_t n)
{
    while (periods <= n) {
        __asm__ volatile("wfi");
    }
}

/* SysTick ticks from a counter value read earlier (less than one period ago; it counts down). */
static uint32_t ticks_since(uint32_t start)
{
    uint32_t now = SYST_CVR;
    return start >= now ? start - now : start + PERIOD_TICKS - now;
}
#else
#define ON_TARGET 0
#endif

/* Deterministic noise, +-amplitude (LCG; the same sequence on every platform). */
static uint32_t seed = 2024u;
static int32_t noise(int32_t amplitude)
{
    seed = seed * 1664525u + 1013904223u;
    return (int32_t)(seed >> 16) % (2 * amplitude + 1) - amplitude;
}

/* mdegC: ramp 0.5 degC/s from max - 10 degC to max + 10 degC (40 s), back down (40 s), hold. */
static int32_t temperature_at(uint32_t n)
{
    const int32_t start = PRIMARY_VALID_TEMP_MAX_MDEGC - 10000;
    uint32_t t_ms = n * (1000u / RATE_HZ);
    if (t_ms < 40000u) {
        return start + (int32_t)(t_ms / 2u);
    }
    if (t_ms < 80000u) {
        return start + 20000 - (int32_t)((t_ms - 40000u) / 2u);
    }
    return start;
}

static void sample_imu(uint32_t n, int32_t accel_q4ug[GNC_AXES], int32_t *temp_mdegc)
{
    int32_t t = temperature_at(n);
    int32_t d = (t - 20000) / 1000; /* degC from 20 */
    *temp_mdegc = t + noise(20);
    accel_q4ug[0] = -32000 + 800 * d + noise(8000);  /* -2 mg, +0.05 mg/degC, +-0.5 mg noise */
    accel_q4ug[1] = 16000 - 480 * d + noise(8000);   /* +1 mg, -0.03 mg/degC */
}

static void telecommand(uint32_t n)
{
    int status;
    const char *id;
    if (n == 60u * RATE_HZ) {
        id = alt_model_id();
    } else if (n == 90u * RATE_HZ) {
        id = unknown_model_id;
    } else if (n == 100u * RATE_HZ) {
        id = primary_model_id();
    } else {
        return;
    }
    status = gnc_tdc_select(id);
    printf("t=%3lus select %.23s...: %s\n", (unsigned long)(n / RATE_HZ), id, status == 0 ? "ok" : "refused");
}

int main(void)
{
    static const char quality_code[] = "CFHR"; /* compensated, fallback, held edge, raw */
    uint32_t n;
    uint32_t checksum = 0u;
#if ON_TARGET
    uint32_t worst_ticks = 0u;
    uint64_t total_ticks = 0u;
#endif
    /* Boot: the unit's calibration record names the model to use (here: the primary one). */
    int status = gnc_tdc_boot(primary_model_id());
    printf("boot: model %.23s... %s; valid %ld .. %ld mdegC\n", primary_model_id(), status == 0 ? "active" : "unknown",
        (long)PRIMARY_VALID_TEMP_MIN_MDEGC, (long)PRIMARY_VALID_TEMP_MAX_MDEGC);
#if ON_TARGET
    start_200hz_tick();
#endif
    for (n = 0u; n < N_SAMPLES; ++n) {
        int32_t accel[GNC_AXES];
        int32_t temp;
        gnc_accel_sample_t out;
#if ON_TARGET
        uint32_t t0;
        uint32_t used;
        wait_for_period(n);
#endif
        telecommand(n); /* between samples, as a ground command handler would */
#if ON_TARGET
        t0 = SYST_CVR;
#endif
        sample_imu(n, accel, &temp);
        gnc_tdc_sensor_task(accel, temp, &out);
#if ON_TARGET
        used = ticks_since(t0);
        worst_ticks = used > worst_ticks ? used : worst_ticks;
        total_ticks += used;
#endif
        checksum = (checksum ^ (uint32_t)out.accel_q4ug[0]) * 16777619u;
        checksum = (checksum ^ (uint32_t)out.accel_q4ug[1]) * 16777619u;
        if (n % REPORT_EVERY == 0u) {
            printf("t=%3lus T=%6ld mdegC x=%9ld %c y=%9ld %c (1/16 ug)\n", (unsigned long)(n / RATE_HZ), (long)temp,
                (long)out.accel_q4ug[0], quality_code[out.quality[0]], (long)out.accel_q4ug[1],
                quality_code[out.quality[1]]);
        }
    }
    {
        const gnc_tdc_health_t *h = gnc_tdc_health();
        printf("health: out_of_range %lu clamped %lu saturated %lu fallback %lu held %lu raw %lu rejected %lu\n",
            (unsigned long)h->temp_out_of_range, (unsigned long)h->input_clamped, (unsigned long)h->saturated,
            (unsigned long)h->fallback, (unsigned long)h->held, (unsigned long)h->raw,
            (unsigned long)h->rejected_switches);
    }
    printf("checksum %08lx over %lu samples\n", (unsigned long)checksum, (unsigned long)N_SAMPLES);
#if ON_TARGET
    printf("cpu: sensor task (2 axes x 2 models + demo I/O) %lu instructions worst, %lu average per 5 ms period\n",
        (unsigned long)(worst_ticks * 40u), (unsigned long)(total_ticks * 40u / N_SAMPLES));
#endif
    return 0;
}
