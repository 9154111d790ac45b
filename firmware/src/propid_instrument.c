/* The motor commands as an instrument for the rotor input (docs/math.md §16).
 *
 * The telemetry's error e_i enters the regressor u_i = Omega_i^2 of every gyro
 * update and attenuates kf and km towards 0 (errors in variables, math.md §14).
 * A value computed from the motor commands alone carries none of e_i. Per rotor
 * a first stage maps the command c_i to the telemetry: the rotor speed follows
 * its command with a first-order lag (config.motor_command_lag), s_i, and
 *   u_i / max_rotor_speed^2 = a_i + b_i z_i + c_i z_i^2,   z_i = s_i - 1/2
 * (an affine speed map squared), fitted by exponentially weighted least squares
 * (config.motor_command_memory: battery sag moves the map during a flight) on
 * the INCREMENTS between rotor samples for b and c (the gyro updates weigh the
 * input's increments: with the rate's process noise they regress the rate's
 * increments on the torque's, so the first stage must be a projection in that
 * sense for its residual to be orthogonal to the value the filter uses; a fit of
 * the levels is dominated by the slow collective and leaves the fast part's lag
 * error in the residual) and on the levels' weighted means for a. The
 * fitted value replaces u_i, as the second stage of two-stage least squares
 * does: the filter's own covariance, update and repair are unchanged, so the
 * symmetric covariance holds it (an instrumental-variable gain P z / (h P z + R)
 * would not be symmetric). Each rotor sample is projected with the fit of the
 * samples before it and only then joins the fit: its projected value contains
 * no part of its own telemetry error.
 *
 * The fit is kept as 9 moments per rotor, not as a recursive covariance: a
 * forgetting recursive least squares winds up in float32 when the commands
 * barely move (hover), the moments with z centred on 1/2 do not. The 2 x 2
 * normal equations of b, c are solved per rotor sample with a ridge of
 * PROPID_INSTRUMENT_RIDGE (hover: z^2's increments are nearly collinear with
 * z's; the ridge then keeps b, c finite, the value still a function of the
 * commands alone).
 *
 * Weak-instrument guard (config.motor_command_min_f > 0): a first stage that
 * explains little of its rotor's increments is a weak instrument, and its own
 * estimation noise (relative variance of the fitted slope ~ 1/(k F)) enters the
 * filter as a slowly varying scale error of that rotor's input. The fit's F
 * statistic, (explained / k) / (residual / (n_eff - k)) with k = 2 regressors
 * and the Kish effective count n_eff = (sum w)^2 / sum w^2 of the forgetting
 * weights, must reach the threshold; otherwise the rotor keeps its telemetry. */
#include <math.h>

#include "propid_instrument.h"

/* Rotor samples in the fit before its value replaces the telemetry. */
#define PROPID_INSTRUMENT_MIN_SAMPLES 50u
/* Ridge of the z and z^2 terms, relative to the fit's weight. */
#define PROPID_INSTRUMENT_RIDGE 1.0e-6f
/* (The usual propid_filter.c checks; without the instrument only the
 * configuration refusal remains.) */

static int is_initialised(const propid_filter_t *filter)
{
    return filter->magic == PROPID_MAGIC;
}

static propid_status_t refuse(propid_filter_t *filter, propid_status_t status)
{
    filter->counters.rejected[PROPID_REJECT_SLOT(status)]++;
    return status;
}

#if PROPID_WITH_INSTRUMENT
void propid_instrument_clear(propid_filter_t *filter)
{
    propid_instrument_t *instrument = &filter->instrument;
    for (uint8_t i = 0; i < PROPID_MAX_ROTORS; ++i) {
        instrument->command[i] = 0.0f;
        instrument->lagged[i] = 0.0f;
        for (uint8_t k = 0; k < PROPID_INSTRUMENT_MOMENTS; ++k) {
            instrument->moment[i][k] = 0.0f;
        }
        for (uint8_t k = 0; k < 3u; ++k) {
            instrument->previous[i][k] = 0.0f;
        }
    }
    instrument->command_time_us = 0u;
    instrument->fit_time_us = 0u;
    instrument->weight_sq = 0.0f;
    instrument->fit_samples = 0u;
    instrument->has_command = 0u; /* (the three counts are kept, like counters) */
}
#endif

propid_status_t propid_push_motor_command(propid_filter_t *filter, uint64_t time_us,
                                          const float *command, uint8_t rotor_count)
{
    if (filter == NULL) {
        return PROPID_ERR_NULL;
    }
    if (!is_initialised(filter)) {
        return PROPID_ERR_NOT_INITIALISED;
    }
#if PROPID_WITH_INSTRUMENT
    if (!filter->config.motor_command_instrument) {
        return refuse(filter, PROPID_ERR_CONFIG);
    }
    if (command == NULL) {
        return refuse(filter, PROPID_ERR_NULL);
    }
    if (rotor_count != filter->config.rotor_count) {
        return refuse(filter, PROPID_ERR_ROTOR_COUNT);
    }
    for (uint8_t i = 0; i < rotor_count; ++i) {
        if (!isfinite(command[i])) {
            return refuse(filter, PROPID_ERR_NOT_FINITE);
        }
        if (command[i] < 0.0f || command[i] > 1.0f) {
            return refuse(filter, PROPID_ERR_ROTOR_SPEED_RANGE);
        }
    }
    propid_instrument_t *instrument = &filter->instrument;
    if (instrument->has_command && time_us <= instrument->command_time_us) {
        return refuse(filter, PROPID_ERR_TIME_BACKWARDS);
    }
    /* The lag's output at this stamp, the previous command held over the
     * interval; after a gap longer than max_gyro_gap_us (or first) it starts at
     * the new command's steady state. */
    const uint64_t gap_us = time_us - instrument->command_time_us;
    const int continues = instrument->has_command && gap_us <= (uint64_t)filter->config.max_gyro_gap_us;
    const float decay = continues ? expf(-(float)gap_us * 1.0e-6f / filter->config.motor_command_lag) : 0.0f;
    for (uint8_t i = 0; i < rotor_count; ++i) {
        const float held = continues ? instrument->command[i] : command[i];
        instrument->lagged[i] = held + (instrument->lagged[i] - held) * decay;
        instrument->command[i] = command[i];
    }
    instrument->command_time_us = time_us;
    instrument->has_command = 1u;
    instrument->command_accepted++;
    return PROPID_OK;
#else
    (void)time_us;
    (void)command;
    (void)rotor_count;
    return refuse(filter, PROPID_ERR_CONFIG); /* compiled out: the option cannot be on */
#endif
}

#if PROPID_WITH_INSTRUMENT

/* What the first stage gives a rotor sample. */
typedef enum {
    FIRST_STAGE_NONE = 0, /* singular increments' equations: the telemetry */
    FIRST_STAGE_VALUE,    /* the fit's value */
    FIRST_STAGE_WEAK      /* the fit fails the weak-instrument guard: the telemetry */
} first_stage_t;

/* a + b z + c z^2 of the fit in m (moment layout in propid.h): b and c from the
 * increments (2 x 2 normal equations with the ridge), a from the weighted means;
 * with min_f > 0 only if the increments' F statistic over the effective count
 * (sum w)^2 / weight_sq reaches min_f. */
static first_stage_t first_stage_value(const float *m, float z, float weight_sq, float min_f, float *value)
{
    const float weight = m[0];
    const float ridge = PROPID_INSTRUMENT_RIDGE * (m[4] + m[6]);
    const float s11 = m[4] + ridge;
    const float s12 = m[5];
    const float s22 = m[6] + ridge;
    const float det = s11 * s22 - s12 * s12;
    if (!(weight > 0.0f) || !(s11 > 0.0f) || !(det > 1.0e-6f * s11 * s22)) {
        return FIRST_STAGE_NONE;
    }
    const float inv_det = 1.0f / det;
    const float b = (s22 * m[7] - s12 * m[8]) * inv_det;
    const float c = (s11 * m[8] - s12 * m[7]) * inv_det;
    const float inv_weight = 1.0f / weight;
    const float a = (m[3] - b * m[1] - c * m[2]) * inv_weight;
    const float result = a + z * (b + z * c);
    if (!isfinite(result)) {
        return FIRST_STAGE_NONE;
    }
    if (min_f > 0.0f) {
        /* F >= min_f as explained (n_eff - 2) >= 2 min_f residual (no division).
         * explained = b S_zy + c S_z2y, in float32 summed as dz's part plus the
         * part of dz2 orthogonal to dz (two non-negative terms): near hover dz2 is
         * nearly collinear with dz, and b S_zy, c S_z2y are then large and cancel. */
        const float cross = s11 * m[8] - s12 * m[7];
        const float explained = m[7] * m[7] / s11 + cross * cross * inv_det / s11;
        const float residual = m[9] - explained;
        const float n_eff = weight_sq > 0.0f ? weight * weight / weight_sq : 0.0f;
        if (!(explained * (n_eff - 2.0f) >= 2.0f * min_f * residual)) {
            return FIRST_STAGE_WEAK;
        }
    }
    *value = result;
    return FIRST_STAGE_VALUE;
}

void propid_instrument_input(propid_filter_t *filter, uint64_t time_us, const float *speed_rad_s,
                             float *speed_sq)
{
    const propid_kept_config_t *config = &filter->config;
    const uint8_t rotor_count = config->rotor_count;
    for (uint8_t i = 0; i < rotor_count; ++i) {
        speed_sq[i] = speed_rad_s[i] * speed_rad_s[i];
    }
    propid_instrument_t *instrument = &filter->instrument;
    if (!config->motor_command_instrument || !instrument->has_command ||
        time_us > instrument->command_time_us + (uint64_t)config->rotor_stale_us) {
        return; /* no fresh command: the telemetry as measured, and no fit */
    }
    const float decay = time_us > instrument->command_time_us
                            ? expf(-(float)(time_us - instrument->command_time_us) * 1.0e-6f / config->motor_command_lag)
                            : 1.0f;
    float forget = 0.0f; /* the first sample starts the fit */
    if (instrument->fit_samples > 0u) {
        forget = time_us > instrument->fit_time_us
                     ? expf(-(float)(time_us - instrument->fit_time_us) * 1.0e-6f / config->motor_command_memory)
                     : 1.0f;
    }
    const float full_sq = config->max_rotor_speed * config->max_rotor_speed;
    const float scale = 1.0f / full_sq;
    const int valid = instrument->fit_samples >= PROPID_INSTRUMENT_MIN_SAMPLES;
    uint8_t projected = 0u;
    for (uint8_t i = 0; i < rotor_count; ++i) {
        float *m = instrument->moment[i];
        const float held = instrument->command[i];
        const float z = held + (instrument->lagged[i] - held) * decay - 0.5f;
        const float y = speed_sq[i] * scale;
        float value = 0.0f;
        const first_stage_t stage = valid ? first_stage_value(m, z, instrument->weight_sq,
                                                              config->motor_command_min_f, &value)
                                          : FIRST_STAGE_NONE;
        if (stage == FIRST_STAGE_VALUE) {
            value = value < 0.0f ? 0.0f : (value > 1.0f ? 1.0f : value);
            speed_sq[i] = value * full_sq;
            projected++;
        } else if (stage == FIRST_STAGE_WEAK && instrument->guarded < UINT32_MAX) {
            instrument->guarded++;
        }
        const float z2 = z * z;
        /* Levels (for a) always; increments from the previous sample of the fit. */
        const float dz = z - instrument->previous[i][0];
        const float dz2 = z2 - instrument->previous[i][1];
        const float dy = y - instrument->previous[i][2];
        const float have_increment = instrument->fit_samples > 0u ? 1.0f : 0.0f;
        const float term[PROPID_INSTRUMENT_MOMENTS] = {
            1.0f, z, z2, y, have_increment * dz * dz, have_increment * dz * dz2, have_increment * dz2 * dz2,
            have_increment * dz * dy, have_increment * dz2 * dy, have_increment * dy * dy};
        for (uint8_t k = 0; k < PROPID_INSTRUMENT_MOMENTS; ++k) {
            m[k] = forget * m[k] + term[k];
        }
        instrument->previous[i][0] = z;
        instrument->previous[i][1] = z2;
        instrument->previous[i][2] = y;
    }
    instrument->weight_sq = forget * forget * instrument->weight_sq + 1.0f;
    instrument->fit_time_us = time_us;
    if (instrument->fit_samples < UINT32_MAX) {
        instrument->fit_samples++;
    }
    if (projected == rotor_count) {
        instrument->inputs++;
    }
}

#endif /* PROPID_WITH_INSTRUMENT */
