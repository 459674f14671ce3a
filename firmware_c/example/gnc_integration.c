/*
 * gnc_integration.c -- see gnc_integration.h. Portable C99: the same file runs on the Cortex-M4
 * build (QEMU mps2-an386) and on the host, and gives the same outputs on both.
 *
 * Design choices, in the order a reviewer will ask about them:
 *  - Every compiled-in model steps on every sample, on each axis. A streaming model (DLSTM) keeps
 *    a continuous window and network state, so switching to it or falling back from it is
 *    bumpless, with no warm-up. Cost: the sum of the models (see docs/firmware.md). A firmware
 *    short of CPU can step only the active model; after a switch it must then treat the first
 *    NAME_WINDOW samples and a few network steps of a streaming model as a warm-up.
 *  - The modules' sample rate is checked at compile time (NAME_CHECK_SAMPLE_RATE_MILLIHZ): a streaming
 *    model stepped at another rate than it was exported for would smooth, step and filter wrongly.
 *  - The module's flags are sticky; the task reads and clears them after every step, so they
 *    describe that one sample and the counters below count samples.
 *  - A streaming model's first seconds after init are a start-up transient (its LSTM state starts
 *    at zero; docs/trainer.md measures up to 12 s): during PRIMARY_WARMUP_S / ALT_WARMUP_S seconds
 *    (15 for a streaming model, 0 for a memoryless one; set by the Makefile) its output is treated
 *    as unusable, in range or not, and the other model or the raw value is used.
 *  - Outside the active model's valid temperature range (the range it was trained on) the module
 *    still computes, and its output is not validated. The task uses the other model when that one
 *    is in range (quality FALLBACK). When neither is, a model that holds its edge
 *    (NAME_HOLDS_EDGE_BEYOND_RANGE 1u: a cubic or physics module clamps the temperature to its valid
 *    range and keeps the edge's correction, as PX4 and ArduPilot clamp to TMIN..TMAX) is used, the
 *    active one first (quality HELD), and the raw value only when neither holds its edge (a PLA
 *    extends its end segments, a network's inputs are clamped to its front end's limits: their
 *    output there is extrapolated). Why not raw at once: the accelerometer's ordinary calibration
 *    (offset, scale) is done on compensated data, so the raw value carries the whole drift from the
 *    model's T_ref, a bias step into the navigation filter at the range's edge; the held edge keeps
 *    the correction continuous there and is off only by the drift beyond the edge.
 *  - A saturated output is never used (FLAG_SATURATED), in range or held.
 */
#include "gnc_integration.h"

#include <stddef.h>
#include <string.h>

#include "tdc_models.h"

#ifndef PRIMARY_WARMUP_S
#define PRIMARY_WARMUP_S 15u
#endif
#ifndef ALT_WARMUP_S
#define ALT_WARMUP_S 0u
#endif
#define GNC_RATE_HZ 200u

/* The rate contract: both modules must be built for this task's rate (codegen export --rate 200);
 * a module built for another rate stops the build here, naming NAME_built_for_another_sample_rate. */
PRIMARY_CHECK_SAMPLE_RATE_MILLIHZ(GNC_RATE_HZ * 1000u);
ALT_CHECK_SAMPLE_RATE_MILLIHZ(GNC_RATE_HZ * 1000u);

enum { MODEL_NONE = -1, MODEL_PRIMARY = 0, MODEL_ALT = 1 };

/* One axis: its own state for each model (never shared between axes). */
typedef struct {
    primary_state_t primary;
    alt_state_t alt;
} axis_t;

static axis_t axes[GNC_AXES];
static uint32_t warmup_primary; /* samples of warm-up left (the same for every axis) */
static uint32_t warmup_alt;
static int active = MODEL_NONE;
static gnc_tdc_health_t health;

static int find_model(const char *model_id)
{
    if (model_id == NULL) {
        return MODEL_NONE;
    }
    if (strcmp(model_id, primary_model_id()) == 0) {
        return MODEL_PRIMARY;
    }
    if (strcmp(model_id, alt_model_id()) == 0) {
        return MODEL_ALT;
    }
    return MODEL_NONE;
}

int gnc_tdc_boot(const char *model_id)
{
    uint32_t k;
    for (k = 0u; k < GNC_AXES; ++k) {
        primary_init(&axes[k].primary);
        alt_init(&axes[k].alt);
    }
    warmup_primary = PRIMARY_WARMUP_S * GNC_RATE_HZ;
    warmup_alt = ALT_WARMUP_S * GNC_RATE_HZ;
    memset(&health, 0, sizeof health);
    active = find_model(model_id);
    return active == MODEL_NONE ? -1 : 0;
}

int gnc_tdc_select(const char *model_id)
{
    int model = find_model(model_id);
    if (model == MODEL_NONE) {
        health.rejected_switches += 1u;
        return -1;
    }
    active = model;
    return 0;
}

const char *gnc_tdc_active_model_id(void)
{
    if (active == MODEL_PRIMARY) {
        return primary_model_id();
    }
    return active == MODEL_ALT ? alt_model_id() : NULL;
}

/* What one model's output of a sample can be used as. */
enum { USE_NONE = 0, USE_HELD = 1, USE_IN_RANGE = 2 };

/* Read and clear one model's flags; count them; what its output of this sample is: in range (neither
 * out of range nor saturated), held (out of range, not saturated, and the module holds its edge
 * beyond its valid range), or not usable. */
static int usable(uint32_t *flags, uint32_t out_of_range, uint32_t clamped, uint32_t saturated, int holds_edge)
{
    uint32_t f = *flags;
    *flags = 0u;
    health.temp_out_of_range += (f & out_of_range) != 0u ? 1u : 0u;
    health.input_clamped += (f & clamped) != 0u ? 1u : 0u;
    health.saturated += (f & saturated) != 0u ? 1u : 0u;
    if ((f & saturated) != 0u) {
        return USE_NONE;
    }
    if ((f & out_of_range) == 0u) {
        return USE_IN_RANGE;
    }
    return holds_edge ? USE_HELD : USE_NONE;
}

void gnc_tdc_sensor_task(const int32_t accel_q4ug[GNC_AXES], int32_t temp_mdegc, gnc_accel_sample_t *out)
{
    uint32_t k;
    int warm_primary = warmup_primary == 0u;
    int warm_alt = warmup_alt == 0u;
    warmup_primary -= warm_primary ? 0u : 1u;
    warmup_alt -= warm_alt ? 0u : 1u;
    for (k = 0u; k < GNC_AXES; ++k) {
        axis_t *axis = &axes[k];
        int32_t y_primary = primary_step(&axis->primary, accel_q4ug[k], temp_mdegc);
        int32_t y_alt = alt_step(&axis->alt, accel_q4ug[k], temp_mdegc);
        int use_primary = usable(&axis->primary.flags, PRIMARY_FLAG_TEMP_OUT_OF_RANGE, PRIMARY_FLAG_INPUT_CLAMPED,
            PRIMARY_FLAG_SATURATED, PRIMARY_HOLDS_EDGE_BEYOND_RANGE != 0u);
        int use_alt = usable(&axis->alt.flags, ALT_FLAG_TEMP_OUT_OF_RANGE, ALT_FLAG_INPUT_CLAMPED, ALT_FLAG_SATURATED,
            ALT_HOLDS_EDGE_BEYOND_RANGE != 0u);
        int use_active;
        int use_other;
        int32_t y_active;
        int32_t y_other;
        use_primary = warm_primary ? use_primary : USE_NONE;
        use_alt = warm_alt ? use_alt : USE_NONE;
        use_active = active == MODEL_PRIMARY ? use_primary : use_alt;
        use_other = active == MODEL_PRIMARY ? use_alt : use_primary;
        y_active = active == MODEL_PRIMARY ? y_primary : y_alt;
        y_other = active == MODEL_PRIMARY ? y_alt : y_primary;
        if (active != MODEL_NONE && use_active == USE_IN_RANGE) {
            out->accel_q4ug[k] = y_active;
            out->quality[k] = GNC_ACCEL_COMPENSATED;
        } else if (active != MODEL_NONE && use_other == USE_IN_RANGE) {
            out->accel_q4ug[k] = y_other;
            out->quality[k] = GNC_ACCEL_FALLBACK;
            health.fallback += 1u;
        } else if (active != MODEL_NONE && (use_active == USE_HELD || use_other == USE_HELD)) {
            out->accel_q4ug[k] = use_active == USE_HELD ? y_active : y_other;
            out->quality[k] = GNC_ACCEL_HELD;
            health.held += 1u;
        } else {
            out->accel_q4ug[k] = accel_q4ug[k];
            out->quality[k] = GNC_ACCEL_RAW;
            health.raw += 1u;
        }
    }
}

const gnc_tdc_health_t *gnc_tdc_health(void)
{
    return &health;
}
