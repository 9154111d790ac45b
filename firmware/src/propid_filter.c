/* Life cycle and input guards. Every rejection is decided before the first write,
 * so a negative status leaves config, derived and core bit-for-bit unchanged and
 * only moves counters.rejected[PROPID_REJECT_SLOT(status)]. */
#include <math.h>
#include <stddef.h>
#include <string.h>

#include "propid_delay.h"
#include "propid_internal.h"
#include "propid_consistency.h"
#include "propid_instrument.h"

static int initialised(const propid_filter_t *filter)
{
    return filter->magic == PROPID_MAGIC;
}

static propid_status_t reject(propid_filter_t *filter, propid_status_t status)
{
    filter->counters.rejected[PROPID_REJECT_SLOT(status)]++;
    return status;
}

static void core_to_prior(propid_filter_t *filter)
{
    propid_core_t *core = &filter->core;
    memset(core, 0, sizeof(*core));
    propid_cov_set_prior(&filter->derived, &filter->config, core);
    core->stale_mark = filter->counters.rejected[PROPID_REJECT_SLOT(PROPID_ERR_ROTOR_STALE)];
#if PROPID_DELAY_SLOTS > 0
    propid_delay_clear(filter);
#endif
#if PROPID_CONSISTENCY
    propid_consistency_reset(filter);
#endif
#if PROPID_WITH_INSTRUMENT
    propid_instrument_clear(filter);
#endif
}

propid_status_t propid_init(propid_filter_t *filter, const propid_config_t *config)
{
    if (filter == NULL || config == NULL) {
        if (filter != NULL && initialised(filter)) {
            return reject(filter, PROPID_ERR_NULL);
        }
        return PROPID_ERR_NULL;
    }
    /* Validate first (nothing written on a bad config), then derive in place: one
     * propid_derived_t on the stack instead of two. */
    if (propid_config_derive(config, NULL, NULL) != PROPID_OK) {
        if (initialised(filter)) {
            return reject(filter, PROPID_ERR_CONFIG);
        }
        return PROPID_ERR_CONFIG;
    }
    memset(filter, 0, sizeof(*filter));
    (void)propid_config_derive(config, &filter->derived, NULL);
    propid_config_keep(config, &filter->config);
    core_to_prior(filter);
    filter->magic = PROPID_MAGIC;
    return PROPID_OK;
}

propid_status_t propid_init_prepared(propid_filter_t *filter, const propid_setup_t *setup)
{
    if (filter == NULL || setup == NULL) {
        if (filter != NULL && initialised(filter)) {
            return reject(filter, PROPID_ERR_NULL);
        }
        return PROPID_ERR_NULL;
    }
    if (!propid_setup_usable(setup)) {
        if (initialised(filter)) {
            return reject(filter, PROPID_ERR_CONFIG);
        }
        return PROPID_ERR_CONFIG;
    }
    memset(filter, 0, sizeof(*filter));
    filter->derived = setup->derived;
    filter->config = setup->config;
    core_to_prior(filter);
    filter->magic = PROPID_MAGIC;
    return PROPID_OK;
}

propid_status_t propid_reset(propid_filter_t *filter)
{
    if (filter == NULL) {
        return PROPID_ERR_NULL;
    }
    if (!initialised(filter)) {
        return PROPID_ERR_NOT_INITIALISED;
    }
    core_to_prior(filter);
    return PROPID_OK;
}

propid_status_t propid_reset_rotor(propid_filter_t *filter, uint8_t rotor)
{
    if (filter == NULL) {
        return PROPID_ERR_NULL;
    }
    if (!initialised(filter)) {
        return PROPID_ERR_NOT_INITIALISED;
    }
    const uint8_t rotor_count = filter->config.rotor_count;
    if (rotor >= rotor_count) {
        return reject(filter, PROPID_ERR_ROTOR_INDEX);
    }
    propid_cov_reset_rotor(&filter->derived, &filter->config, &filter->core, rotor, 1);
#if PROPID_CONSISTENCY
    propid_consistency_restart(filter);
#endif
    return PROPID_OK;
}

propid_status_t propid_resync(propid_filter_t *filter, uint64_t time_us)
{
    if (filter == NULL) {
        return PROPID_ERR_NULL;
    }
    if (!initialised(filter)) {
        return PROPID_ERR_NOT_INITIALISED;
    }
    propid_core_t *core = &filter->core;
    /* The rates drifted during the gap: forget them and their correlations, prior
     * variance. The next gyro sample anchors the clock and sets the rates again. */
    for (uint8_t a = 0; a < PROPID_RATE_STATES; ++a) {
        core->state[a] = 0.0f;
        propid_cov_reset_state(&filter->derived, core, a);
        core->gated_run[a] = 0u;
    }
    core->time_us = time_us;
    core->has_time = 0u;
#if PROPID_DELAY_SLOTS > 0
    propid_delay_clear(filter); /* held samples belong to the time before the gap */
#endif
    core->health |= PROPID_HEALTH_TIME_RESYNCED;
    filter->counters.resyncs++;
    return PROPID_OK;
}

/* Every check of a rotor sample (nothing written unless it passes; rejections
 * counted). Not inlined, like the gyro's: the push functions' own frames stay
 * small because held IMU samples are fused under them (propid_delay.h). */
static __attribute__((noinline)) propid_status_t rotor_sample_check(propid_filter_t *filter, uint64_t time_us,
                                                                    const float *rotor_speed_rad_s,
                                                                    uint8_t rotor_count)
{
    if (filter == NULL) {
        return PROPID_ERR_NULL;
    }
    if (!initialised(filter)) {
        return PROPID_ERR_NOT_INITIALISED;
    }
    if (rotor_speed_rad_s == NULL) {
        return reject(filter, PROPID_ERR_NULL);
    }
    const propid_kept_config_t *config = &filter->config;
    if (rotor_count != config->rotor_count) {
        return reject(filter, PROPID_ERR_ROTOR_COUNT);
    }
    for (uint8_t i = 0; i < rotor_count; ++i) {
        const float speed = rotor_speed_rad_s[i];
        if (!isfinite(speed)) {
            return reject(filter, PROPID_ERR_NOT_FINITE);
        }
        if (speed < 0.0f) {
            return reject(filter, PROPID_ERR_ROTOR_SPEED_NEGATIVE);
        }
        if (speed > config->max_rotor_speed) {
            return reject(filter, PROPID_ERR_ROTOR_SPEED_RANGE);
        }
    }
    const propid_core_t *core = &filter->core;
    const uint64_t max_gap = config->max_gyro_gap_us;
    /* Stamps on the rotor clock of the filter: shifted by |delay| when the gyro lags. */
    const uint64_t stamp = time_us + propid_delay_rotor_shift(config);
    uint64_t previous = core->rotor_time_us;
    int has_previous = core->has_rotor_data;
#if PROPID_DELAY_SLOTS > 0
    const int held = propid_delay_newest(filter, PROPID_DELAY_ROTOR, &previous);
    has_previous |= held;
#endif
    if (has_previous && stamp <= previous) {
        /* Not after the previous sample: going backwards, unless the stored
         * stamp is the fault, more than max_gyro_gap_us ahead of the gyro clock
         * (or, before the clock is anchored, of this sample). Such data is never
         * used (propid_push_gyro finds it stale, which raises ROTOR_STALE), and
         * this sample replaces it: one wild stamp must not lock out the stream. */
        const uint64_t reference = core->has_time ? core->time_us + propid_delay_imu_shift(config) : stamp;
        if (!(previous > reference && previous - reference > max_gap)) {
            return reject(filter, PROPID_ERR_TIME_BACKWARDS);
        }
#if PROPID_DELAY_SLOTS > 0
        if (held) {
            propid_delay_clear(filter); /* the held samples follow the wild one */
        }
#endif
        return PROPID_OK;
    }
#if PROPID_DELAY_SLOTS > 0
    if (held) {
        return PROPID_OK; /* the previous speeds wait in the delay buffer: no slew test */
    }
#endif
    /* A speed no motor can reach from the previous sample in the time between
     * them (a corrupted telemetry frame within range, "ESC spike"): fused, it
     * would make the coefficients look observed through a wrong input and throw
     * them far off without any gated innovation. The speed loop is a first-order
     * lag of time constant tau towards a command in [0, max_rotor_speed]: from
     * w0 it covers at most the fraction 1 - exp(-dt / tau) <= dt / tau of its
     * headroom, max_rotor_speed - w0 up and w0 down (tau divided by
     * PROPID_MOTOR_SPEEDUP for margin), plus the telemetry's resolution at the
     * bottom of the range (PROPID_SLEW_FLOOR of max_rotor_speed: a DShot eRPM
     * frame reads 0 below its longest period). Once dt reaches that tau the
     * bound is the whole range: a refused burst never locks the stream out for
     * longer. */
    if (has_previous) {
        const uint64_t gap = stamp - previous;
        const float reach = (float)(uint32_t)(gap < 0xFFFFFFFFu ? gap : 0xFFFFFFFFu) *
                            (PROPID_MOTOR_SPEEDUP / 100.0f) / (float)filter->derived.motor_tau_100us;
        if (reach < 1.0f) {
            const float resolution = PROPID_SLEW_FLOOR * config->max_rotor_speed;
            for (uint8_t i = 0; i < rotor_count; ++i) {
                const float before = sqrtf(core->rotor_speed_sq[i]);
                const float change = rotor_speed_rad_s[i] - before;
                const float headroom = change > 0.0f ? config->max_rotor_speed - before : before;
                if (!(fabsf(change) <= headroom * reach + resolution)) {
                    return reject(filter, PROPID_ERR_ROTOR_SPEED_RANGE);
                }
            }
        }
    }
    return PROPID_OK;
}

propid_status_t propid_push_rotor_speeds(propid_filter_t *filter, uint64_t time_us,
                                         const float *rotor_speed_rad_s, uint8_t rotor_count)
{
    const propid_status_t checked = rotor_sample_check(filter, time_us, rotor_speed_rad_s, rotor_count);
    if (checked != PROPID_OK) {
        return checked;
    }
    const uint64_t stamp = time_us + propid_delay_rotor_shift(&filter->config);
#if PROPID_WITH_INSTRUMENT
    /* The rotor input: the telemetry squared, or its projection on the motor
     * commands (stamped on the gyro clock, as the commands are). */
    float input_sq[PROPID_MAX_ROTORS];
    propid_instrument_input(filter, time_us, rotor_speed_rad_s, input_sq);
#elif PROPID_DELAY_SLOTS > 0
    float input_sq[PROPID_MAX_ROTORS];
    for (uint8_t i = 0; i < rotor_count; ++i) {
        input_sq[i] = rotor_speed_rad_s[i] * rotor_speed_rad_s[i];
    }
#endif
#if PROPID_DELAY_SLOTS > 0
    if (filter->config.rotor_delay_us < 0) {
        return propid_delay_push_rotor(filter, stamp, input_sq);
    }
    if (filter->config.rotor_delay_us > 0) {
        /* IMU samples of an earlier time are fused with the speeds before this one. */
        propid_delay_release_imu(filter, stamp, 0, 0);
    }
#endif
    propid_core_t *core = &filter->core;
    for (uint8_t i = 0; i < rotor_count; ++i) {
#if PROPID_WITH_INSTRUMENT || PROPID_DELAY_SLOTS > 0
        core->rotor_speed_sq[i] = input_sq[i];
#else
        core->rotor_speed_sq[i] = rotor_speed_rad_s[i] * rotor_speed_rad_s[i];
#endif
    }
    core->rotor_time_us = stamp;
    core->has_rotor_data = 1u;
    filter->counters.rotor_accepted++;
    return PROPID_OK;
}

/* The first sample after init, reset or resync only anchors the clock (no
 * prediction): the state's finiteness test (a non-finite state returns
 * PROPID_ERR_NUMERIC with nothing written) and the row check, then the rates
 * start at this sample (the prior mean of omega given y = omega + b): its
 * innovation is then zero, so it is fused whatever the rate, and the bias is
 * not pulled by an unknown initial rate. Not inlined: this rare path's frame
 * stays off the usual step's. */
static __attribute__((noinline)) PROPID_RARE propid_status_t anchor_step(propid_filter_t *filter, const float gyro_rad_s[3])
{
    propid_core_t *core = &filter->core;
    float check = 0.0f;
    for (uint8_t k = 0; k < filter->derived.state_count; ++k) {
        check += core->state[k];
    }
    if (!isfinite(check)) {
        return PROPID_ERR_NUMERIC;
    }
    core->health &= ~(PROPID_HEALTH_GATED | PROPID_HEALTH_STATE_CLAMPED);
    propid_check_next_row(filter, 0);
    const uint8_t first_bias = propid_first_bias(filter->config.rotor_count);
    for (uint8_t a = 0; a < 3u; ++a) {
        core->state[a] = gyro_rad_s[a] - core->state[first_bias + a];
    }
    return PROPID_OK;
}

/* Time checks of a gyro sample against the previous one (previous: its stamp,
 * or the resync time when anchor): backwards, jump. */
static propid_status_t gyro_time_check(const propid_kept_config_t *config, uint64_t previous, int anchor,
                                       uint64_t time_us)
{
    if (anchor) {
        /* After propid_resync(t) the anchoring sample may carry t itself (the
         * sample that was rejected as a time jump), not an earlier time. */
        return time_us < previous ? PROPID_ERR_TIME_BACKWARDS : PROPID_OK;
    }
    if (time_us <= previous) {
        return PROPID_ERR_TIME_BACKWARDS;
    }
    /* Later: a jump when the difference's high word is set or its low word is
     * beyond the gap (a 64-bit compare takes twice the instructions). */
    const uint64_t gap = time_us - previous;
    return (uint32_t)(gap >> 32) != 0u || (uint32_t)gap > config->max_gyro_gap_us ? PROPID_ERR_TIME_JUMP : PROPID_OK;
}

/* Every check of a gyro sample that does not need the rotor data: pointer,
 * finite, range, time (for a sample to be held, the rotor speeds lagging,
 * against the newest held one, else the filter's clock). Rejections counted.
 * Not inlined with the delay buffer (see rotor_sample_check); without it,
 * propid_push_gyro releases its frame before the step (a tail call), so the
 * checks are inlined there. */
#if PROPID_DELAY_SLOTS > 0
#define PROPID_GYRO_CHECK_LINK __attribute__((noinline))
#else
#define PROPID_GYRO_CHECK_LINK inline __attribute__((always_inline))
#endif
static PROPID_GYRO_CHECK_LINK propid_status_t gyro_sample_check(propid_filter_t *filter, uint64_t time_us,
                                                               const float gyro_rad_s[3])
{
    if (filter == NULL) {
        return PROPID_ERR_NULL;
    }
    if (!initialised(filter)) {
        return PROPID_ERR_NOT_INITIALISED;
    }
    if (gyro_rad_s == NULL) {
        return reject(filter, PROPID_ERR_NULL);
    }
    const propid_kept_config_t *config = &filter->config;
    /* One test per axis for the usual sample, |g| <= gyro_range, on the bit
     * patterns shifted left by one (the sign dropped; gyro_range is positive and
     * finite, so NaN and infinity are above it): a compare of two integers, no
     * float compare and flag transfer; which of the two checks failed is sorted
     * out after. */
    const uint32_t range_bits_2 = propid_float_bits(config->gyro_range) << 1;
    if ((propid_float_bits(gyro_rad_s[0]) << 1) > range_bits_2 || (propid_float_bits(gyro_rad_s[1]) << 1) > range_bits_2 ||
        (propid_float_bits(gyro_rad_s[2]) << 1) > range_bits_2) {
        for (uint8_t a = 0; a < 3u; ++a) {
            if (!isfinite(gyro_rad_s[a])) {
                return reject(filter, PROPID_ERR_NOT_FINITE);
            }
        }
        return reject(filter, PROPID_ERR_GYRO_RANGE);
    }
    uint64_t previous = filter->core.time_us;
    int anchor = !filter->core.has_time;
#if PROPID_DELAY_SLOTS > 0
    if (config->rotor_delay_us > 0 && propid_delay_newest(filter, PROPID_DELAY_GYRO, &previous)) {
        anchor = 0;
    }
#endif
    const propid_status_t timing = gyro_time_check(config, previous, anchor, time_us);
    if (timing != PROPID_OK) {
        return reject(filter, timing);
    }
    return PROPID_OK;
}

/* Without the delay buffer propid_push_gyro is the only caller of the step
 * (fuse_gyro_timed) and takes it inline: one frame, the sample's time and
 * anchor state read once for the checks and the step. With the buffer it is a
 * function of its own, which the buffer's releases call too (propid_fuse_gyro). */
#if PROPID_DELAY_SLOTS > 0
#define PROPID_GYRO_STEP_LINK __attribute__((noinline))
#else
#define PROPID_GYRO_STEP_LINK inline __attribute__((always_inline))
#endif
static PROPID_GYRO_STEP_LINK propid_status_t fuse_gyro_timed(propid_filter_t *filter, uint64_t time_us,
                                                               const float gyro_rad_s[3]);

propid_status_t propid_push_gyro(propid_filter_t *filter, uint64_t time_us,
                                 const float gyro_rad_s[3])
{
    const propid_status_t checked = gyro_sample_check(filter, time_us, gyro_rad_s);
    if (checked != PROPID_OK) {
        return checked;
    }
#if PROPID_DELAY_SLOTS > 0
    if (filter->config.rotor_delay_us > 0) {
        /* Held until the rotor speeds of its time arrive. */
        propid_delay_release_imu(filter, time_us, 1, 1);
        return propid_delay_hold_imu(filter, PROPID_DELAY_GYRO, time_us, gyro_rad_s);
    }
    /* Held rotor samples (the gyro lags) that act by now. */
    propid_delay_release_rotor(filter, time_us);
#endif
    /* Not held: gyro_sample_check has already tested the time against the
     * filter's clock, which is the test propid_fuse_gyro starts with. */
    return fuse_gyro_timed(filter, time_us, gyro_rad_s);
}

#if PROPID_DELAY_SLOTS > 0
propid_status_t propid_fuse_gyro(propid_filter_t *filter, uint64_t time_us, const float gyro_rad_s[3])
{
    const propid_status_t timing =
        gyro_time_check(&filter->config, filter->core.time_us, !filter->core.has_time, time_us);
    if (timing != PROPID_OK) {
        return reject(filter, timing);
    }
    return fuse_gyro_timed(filter, time_us, gyro_rad_s);
}
#endif

#if PROPID_WITH_INPUT_NOISE || PROPID_WITH_GYRO_STUCK_CHECK
/* The gyro update with either rare option (one test in the step for both): the
 * stuck-axis check (config.gyro_stuck_samples: a repeated reading is not fused)
 * and the errors-in-variables compensation (docs/math.md §14: the corrections
 * are formed from the predicted P, added for the fused axes). */
static __attribute__((noinline)) uint32_t update_gyro_rare(propid_filter_t *filter, float dt,
                                                           const float gyro_rad_s[3])
{
    uint32_t skip_mask = 0u;
#if PROPID_WITH_GYRO_STUCK_CHECK
    if (filter->config.gyro_stuck_samples != 0u) {
        skip_mask = propid_gyro_stuck_mask(filter, gyro_rad_s);
    }
#endif
#if PROPID_WITH_INPUT_NOISE
    if (filter->derived.input_compensation) {
        propid_input_compensation_prepare(filter, dt);
    }
#else
    (void)dt;
#endif
#if PROPID_WITH_GYRO_STUCK_CHECK
    const uint32_t not_fused = propid_update_gyro_skipping(filter, gyro_rad_s, skip_mask);
#else
    const uint32_t not_fused = propid_update_gyro(filter, gyro_rad_s) | skip_mask;
#endif
#if PROPID_WITH_INPUT_NOISE
    if (filter->derived.input_compensation) {
        propid_input_compensation_apply(filter, not_fused);
    }
#endif
    return not_fused;
}
#endif

/* 1 when rotor data stamped rotor_time_us is stale at rotor_clock: older than
 * rotor_stale_us, or stamped beyond any plausible gap after it (a clock fault). */
static __attribute__((noinline)) PROPID_RARE int rotor_stale(const propid_filter_t *filter, uint64_t rotor_clock)
{
    const propid_kept_config_t *config = &filter->config;
    const uint64_t rotor_time_us = filter->core.rotor_time_us;
    if (rotor_clock > rotor_time_us) {
        return rotor_clock - rotor_time_us > (uint64_t)config->rotor_stale_us;
    }
    return rotor_time_us - rotor_clock > (uint64_t)config->max_gyro_gap_us;
}

/* The accepted sample's time starts the next interval: its rotor speeds are the
 * latest ones, the stale mark and the clock are the sample's. Whole arrays; on
 * the Cortex-M4 the quad's speeds and the mark, adjacent in propid_core_t, in
 * one load-multiple and one store-multiple and the stamp in one 64-bit store
 * from the same base (GCC makes a load and a store per word of the copy and two
 * stores of the stamp). */
static inline __attribute__((always_inline)) void start_next_interval(propid_core_t *core, uint32_t stale_mark,
                                                                      uint64_t time_us)
{
#if PROPID_ARM_BLOCK_MOVES && PROPID_MAX_ROTORS == 4
    _Static_assert(offsetof(propid_core_t, input_speed_sq) == offsetof(propid_core_t, rotor_speed_sq) + 16u &&
                       offsetof(propid_core_t, stale_mark) == offsetof(propid_core_t, input_speed_sq) + 16u,
                   "the speeds and the stale mark are adjacent");
    float *speeds = core->rotor_speed_sq;
    __asm__ volatile("ldmia %[at]!, {r0, r1, r2, r3}\n\t"
                     "stmia %[at], {r0, r1, r2, r3, %[mark]}\n\t"
                     "strd %Q[time], %R[time], [%[at], %[time_at]]"
                     : [at] "+&r"(speeds)
                     : [mark] "r"(stale_mark), [time] "r"(time_us),
                       [time_at] "i"(offsetof(propid_core_t, time_us) - offsetof(propid_core_t, input_speed_sq))
                     : "r0", "r1", "r2", "r3", "memory");
#else
    memcpy(core->input_speed_sq, core->rotor_speed_sq, sizeof(core->input_speed_sq));
    core->stale_mark = stale_mark;
    core->time_us = time_us;
#endif
}

/* propid_fuse_gyro after its time test (time_us is later than the filter's
 * clock by at most the largest gap, or anchors it). */
static PROPID_GYRO_STEP_LINK propid_status_t fuse_gyro_timed(propid_filter_t *filter, uint64_t time_us,
                                                               const float gyro_rad_s[3])
{
    const propid_kept_config_t *config = &filter->config;
    propid_core_t *core = &filter->core;
    if (!core->has_rotor_data) {
        return reject(filter, PROPID_ERR_NO_ROTOR_DATA);
    }
    /* Rotor data stamped after the gyro sample is the freshest we have (ZOH),
     * unless it is stamped beyond any plausible gap (a clock fault: stale).
     * Compared on the rotor clock (the gyro stamp + the delay when the rotor
     * speeds lag). */
    /* The interval, read where the time check has just read the clock (the
     * compiler reuses its difference); read again after the rare call below. */
    int anchor = !core->has_time; /* first sample after init/reset/resync */
    uint32_t interval_us = (uint32_t)time_us - (uint32_t)core->time_us;
    const uint64_t rotor_clock = time_us + propid_delay_imu_shift(config);
    const uint64_t rotor_age = rotor_clock - core->rotor_time_us; /* wraps when stamped after the gyro */
    if ((uint32_t)(rotor_age >> 32) != 0u || (uint32_t)rotor_age > config->rotor_stale_us) {
        /* Not the usual age (0 .. rotor_stale_us): the full test. */
        if (rotor_stale(filter, rotor_clock)) {
            return reject(filter, PROPID_ERR_ROTOR_STALE);
        }
        /* (Nothing of the checks above kept across this rare call: read again
         * below, no stack for it on the usual path.) */
        PROPID_SCHEDULE_BARRIER();
        anchor = !core->has_time;
        interval_us = (uint32_t)time_us - (uint32_t)core->time_us;
    }
    const float dt = anchor ? 0.0f : (float)interval_us * 1.0e-6f;

    const propid_status_t stepped = anchor ? anchor_step(filter, gyro_rad_s) : propid_predict_step(filter, dt);
    if (stepped != PROPID_OK) {
        return reject(filter, PROPID_ERR_NUMERIC);
    }
    /* Accepted: the filter has changed (prediction); now the measurement. */
#if PROPID_WITH_INPUT_NOISE || PROPID_WITH_GYRO_STUCK_CHECK
    const uint32_t gated_mask = !anchor && filter->derived.rare_gyro_update
                                    ? update_gyro_rare(filter, dt, gyro_rad_s)
                                    : propid_update_gyro(filter, gyro_rad_s);
#else
    const uint32_t gated_mask = propid_update_gyro(filter, gyro_rad_s);
#endif
#if PROPID_CONSISTENCY
    propid_consistency_observe(filter, gated_mask);
#endif
    uint32_t clamped = propid_clamp_coefficients(filter);
#if PROPID_WITH_ACCEL
    clamped += propid_clamp_torque_scale(config, &filter->derived, core);
#endif
    if (clamped != 0u) {
        core->health |= PROPID_HEALTH_STATE_CLAMPED;
        filter->counters.state_clamps += clamped;
    }
    propid_status_t accepted = PROPID_OK;
    if (gated_mask != 0u) {
        core->health |= PROPID_HEALTH_GATED;
        accepted = PROPID_OK_GATED;
    }
    start_next_interval(core, filter->counters.rejected[PROPID_REJECT_SLOT(PROPID_ERR_ROTOR_STALE)], time_us);
    core->has_time = 1u;
    filter->counters.gyro_accepted++;
    return accepted;
}
