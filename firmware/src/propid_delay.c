/* Telemetry delay (docs/math.md §12): a fixed FIFO of the leading stream's
 * samples. One stream is held at a time, by the sign of config.rotor_delay_us:
 * the IMU samples (gyro, accelerometer) when the rotor speeds lag, the rotor
 * samples when the gyro lags. Bounded loops (at most PROPID_DELAY_SLOTS), no
 * allocation; with PROPID_DELAY_SLOTS = 0 only the configuration check remains. */
#include <stddef.h>
#include <string.h>

#include "propid_delay.h"

int propid_delay_config_ok(const propid_config_t *config)
{
    const int32_t delay = config->rotor_delay_us;
    if (delay == 0) {
        return 1;
    }
#if PROPID_DELAY_SLOTS > 0
    /* |d| up to 1 s, and the held stream's samples over |d| must fit with one
     * slot to spare for jitter. Held IMU samples are gyro plus, with the
     * accelerometer configured, at most as many accelerometer samples; held
     * rotor samples are assumed no faster than the gyro (a faster stream
     * overflows: released early, counted in counters.delay_overflows). */
    if (delay < -1000000 || delay > 1000000) {
        return 0;
    }
    const float magnitude_s = (float)(delay < 0 ? -delay : delay) * 1.0e-6f;
    const float streams = (delay > 0 && config->mass > 0.0f) ? 2.0f : 1.0f;
    const float held = magnitude_s * config->gyro_sample_rate_hz * streams;
    return held <= (float)(PROPID_DELAY_SLOTS - 1);
#else
    return 0; /* built without the buffer */
#endif
}

#if PROPID_DELAY_SLOTS > 0

void propid_delay_clear(propid_filter_t *filter)
{
    filter->delay.head = 0u;
    filter->delay.count = 0u;
}

static uint8_t slot(uint8_t head, uint8_t k)
{
    const unsigned index = (unsigned)head + k;
    return (uint8_t)(index >= PROPID_DELAY_SLOTS ? index - PROPID_DELAY_SLOTS : index);
}

int propid_delay_newest(const propid_filter_t *filter, uint8_t kind, uint64_t *time_us)
{
    const propid_delay_t *delay = &filter->delay;
    for (uint8_t k = delay->count; k > 0u; --k) {
        const propid_delay_entry_t *entry = &delay->entry[slot(delay->head, (uint8_t)(k - 1u))];
        if (entry->kind == kind) {
            *time_us = entry->time_us;
            return 1;
        }
    }
    return 0;
}

static propid_delay_entry_t *push_slot(propid_delay_t *delay)
{
    propid_delay_entry_t *entry = &delay->entry[slot(delay->head, delay->count)];
    delay->count++;
    return entry;
}

propid_status_t propid_delay_hold_imu(propid_filter_t *filter, uint8_t kind, uint64_t time_us,
                                      const float values[3])
{
    propid_delay_t *delay = &filter->delay;
    propid_delay_entry_t *entry = push_slot(delay);
    entry->time_us = time_us;
    entry->kind = kind;
    entry->value[0] = values[0];
    entry->value[1] = values[1];
    entry->value[2] = values[2];
    return PROPID_OK_QUEUED;
}

static void apply_oldest_rotor(propid_filter_t *filter)
{
    propid_delay_t *delay = &filter->delay;
    const propid_delay_entry_t *entry = &delay->entry[delay->head];
    propid_core_t *core = &filter->core;
    memcpy(core->rotor_speed_sq, entry->value, sizeof(float) * filter->config.rotor_count);
    core->rotor_time_us = entry->time_us;
    core->has_rotor_data = 1u;
    delay->head = slot(delay->head, 1u);
    delay->count--;
}

propid_status_t propid_delay_push_rotor(propid_filter_t *filter, uint64_t time_us, const float *speed_sq)
{
    propid_delay_t *delay = &filter->delay;
    if (delay->count >= PROPID_DELAY_SLOTS) {
        apply_oldest_rotor(filter);
        filter->counters.delay_overflows++;
    }
    propid_delay_entry_t *entry = push_slot(delay);
    entry->time_us = time_us;
    entry->kind = PROPID_DELAY_ROTOR;
    for (uint8_t i = 0; i < filter->config.rotor_count; ++i) {
        entry->value[i] = speed_sq[i];
    }
    filter->counters.rotor_accepted++;
    return PROPID_OK_QUEUED;
}

void propid_delay_release_rotor(propid_filter_t *filter, uint64_t time_us)
{
    if (filter->config.rotor_delay_us >= 0) {
        return; /* rotor samples are held only when the gyro lags */
    }
    propid_delay_t *delay = &filter->delay;
    for (uint8_t k = 0u; k < PROPID_DELAY_SLOTS && delay->count > 0u; ++k) {
        if (delay->entry[delay->head].time_us > time_us) {
            break;
        }
        apply_oldest_rotor(filter);
    }
}

#endif /* PROPID_DELAY_SLOTS > 0 */
