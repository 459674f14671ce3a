/*
 * gnc_integration.h -- how a GNC firmware uses generated temperature-drift compensators.
 *
 * Two compiled-in models (a primary one and an alternative, see tdc_models.h) compensate two
 * accelerometer axes, each axis with its own state per model. The caller:
 *   - at boot: gnc_tdc_boot(id) with the model id of the unit's calibration record;
 *   - at 200 Hz, from the sensor task, once per IMU sample: gnc_tdc_sensor_task();
 *   - on a telecommand (new calibration uploaded and verified): gnc_tdc_select(id).
 * Every output sample carries a quality that the navigation filter maps to its measurement noise
 * (compensated / fallback model / a model holding its edge beyond its valid range / raw). Not
 * reentrant: call everything from the sensor task.
 *
 * Units as in the generated API: acceleration int32 in 1/16 micro-g, temperature int32 mdegC.
 */
#ifndef GNC_INTEGRATION_H_INCLUDED
#define GNC_INTEGRATION_H_INCLUDED

#include <stdint.h>

#define GNC_AXES 2u /* x and y; the pattern is the same for z */

typedef enum {
    GNC_ACCEL_COMPENSATED = 0, /* the active model, inside its valid temperature range */
    GNC_ACCEL_FALLBACK = 1,    /* the other model (active one out of range, saturated or warming up) */
    GNC_ACCEL_HELD = 2,        /* a model beyond its valid range holding its edge correction, as PX4 and
                                  ArduPilot do (NAME_HOLDS_EDGE_BEYOND_RANGE): inflate the noise */
    GNC_ACCEL_RAW = 3          /* no model applies: raw acceleration (drift from T_ref left in), inflate
                                  its noise more */
} gnc_accel_quality_t;

typedef struct {
    int32_t accel_q4ug[GNC_AXES];
    gnc_accel_quality_t quality[GNC_AXES];
} gnc_accel_sample_t;

/* Event counters for FDIR / housekeeping telemetry (samples, summed over the axes). */
typedef struct {
    uint32_t temp_out_of_range; /* a model reported FLAG_TEMP_OUT_OF_RANGE */
    uint32_t input_clamped;     /* a model reported FLAG_INPUT_CLAMPED (beyond full scale) */
    uint32_t saturated;         /* a model reported FLAG_SATURATED */
    uint32_t fallback;          /* output from the other model, in its valid range */
    uint32_t held;              /* output from a model beyond its valid range, holding its edge */
    uint32_t raw;               /* output uncompensated */
    uint32_t rejected_switches; /* gnc_tdc_select with an unknown model id */
} gnc_tdc_health_t;

/* Initialise every state and make the model with this id active. Returns 0, or -1 when no
 * compiled-in model has the id: then every output is raw until a valid gnc_tdc_select. */
int gnc_tdc_boot(const char *model_id);

/* Switch the active model by id (bumpless: every model runs on every sample). Returns 0, or -1
 * for an unknown id, in which case the active model stays as it was. */
int gnc_tdc_select(const char *model_id);

/* The active model's id ("sha256:..."), or NULL when none is active. */
const char *gnc_tdc_active_model_id(void);

/* One 200 Hz IMU sample: raw accelerations of the axes and the sensor's temperature. */
void gnc_tdc_sensor_task(const int32_t accel_q4ug[GNC_AXES], int32_t temp_mdegc, gnc_accel_sample_t *out);

const gnc_tdc_health_t *gnc_tdc_health(void);

#endif /* GNC_INTEGRATION_H_INCLUDED */
