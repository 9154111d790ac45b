/*
 * Telemetry delay (docs/math.md §12), internal. config.rotor_delay_us = d:
 *   d > 0  the rotor-speed telemetry lags: the speed the body had at t arrives
 *          stamped t + d. Gyro and accelerometer samples wait in the buffer
 *          until the rotor stream has reached t + d, then are fused with the
 *          rotor speeds of that time (compared on the rotor stream's clock:
 *          IMU stamp + d).
 *   d < 0  the gyro lags (e.g. its low-pass filter): a rotor sample stamped s
 *          acts on the gyro at s + |d|. Rotor samples wait in the buffer and
 *          are applied, with time s + |d|, when an IMU sample reaches that time.
 * With PROPID_DELAY_SLOTS = 0 every function here compiles to nothing.
 */
#ifndef PROPID_DELAY_H
#define PROPID_DELAY_H

#include "propid_internal.h"

#define PROPID_DELAY_GYRO 1u
#define PROPID_DELAY_ACCEL 2u
#define PROPID_DELAY_ROTOR 3u

/* Added to an IMU stamp before it is compared with rotor stamps: d when the
 * rotor speeds lag, else 0. */
static inline uint64_t propid_delay_imu_shift(const propid_kept_config_t *config)
{
#if PROPID_DELAY_SLOTS > 0
    return config->rotor_delay_us > 0 ? (uint64_t)config->rotor_delay_us : 0u;
#else
    (void)config;
    return 0u;
#endif
}

/* Added to a rotor stamp: |d| when the gyro lags, else 0. */
static inline uint64_t propid_delay_rotor_shift(const propid_kept_config_t *config)
{
#if PROPID_DELAY_SLOTS > 0
    return config->rotor_delay_us < 0 ? (uint64_t)(-(int64_t)config->rotor_delay_us) : 0u;
#else
    (void)config;
    return 0u;
#endif
}

/* 1 when config.rotor_delay_us fits this build's buffer (propid_config_check). */
int propid_delay_config_ok(const propid_config_t *config);

/* The IMU processing the buffer releases into (propid_filter.c, propid_accel.c):
 * everything after the sample's own input checks. */
propid_status_t propid_fuse_gyro(propid_filter_t *filter, uint64_t time_us, const float gyro_rad_s[3]);
propid_status_t propid_fuse_accel(propid_filter_t *filter, uint64_t time_us, const float specific_force[3]);

#if PROPID_DELAY_SLOTS > 0
/* Empty the buffer (init, reset, resync). */
void propid_delay_clear(propid_filter_t *filter);
/* Stamp of the newest held sample of this kind: 1 and *time_us, or 0 when none. */
int propid_delay_newest(const propid_filter_t *filter, uint8_t kind, uint64_t *time_us);
/* d > 0: hold a validated IMU sample (propid_delay_release_imu has made room);
 * its push then releases what is due at its time. */
propid_status_t propid_delay_hold_imu(propid_filter_t *filter, uint8_t kind, uint64_t time_us,
                                      const float values[3]);
/* d < 0: hold a validated rotor sample's input (speeds squared, or the commands'
 * first stage: propid_instrument.h), release time time_us (a full buffer first
 * applies its oldest early). */
propid_status_t propid_delay_push_rotor(propid_filter_t *filter, uint64_t time_us, const float *speed_sq);
/* d < 0: apply the held rotor samples whose release time is at or before time_us. */
void propid_delay_release_rotor(propid_filter_t *filter, uint64_t time_us);

/* d > 0 (only then: the stamp + d below): fuse the held IMU samples, oldest
 * first, whose rotor-clock time (stamp + d) is at or before time_us (inclusive
 * = 1: an IMU push) or before it (inclusive = 0: a rotor push, before that
 * sample is stored), and with make_room the oldest of a full buffer (early,
 * counted in counters.delay_overflows). Fused in place from the buffer (the
 * fusing never touches it) and inlined into the push functions with few values
 * live across the fusing call: a held sample's step runs under one small frame
 * more than an undelayed one. */
static inline __attribute__((always_inline)) void propid_delay_release_imu(propid_filter_t *filter, uint64_t time_us,
                                                                           int inclusive, int make_room)
{
    /* Bounded: every pass removes one of at most PROPID_DELAY_SLOTS entries. */
    while (filter->delay.count > 0u) {
        const propid_delay_entry_t *entry = &filter->delay.entry[filter->delay.head];
        const uint64_t due = entry->time_us + (uint64_t)filter->config.rotor_delay_us;
        if (inclusive ? due > time_us : due >= time_us) {
            if (!make_room || filter->delay.count < PROPID_DELAY_SLOTS) {
                break;
            }
            filter->counters.delay_overflows++;
        }
        if (entry->kind == PROPID_DELAY_GYRO) {
            (void)propid_fuse_gyro(filter, entry->time_us, entry->value);
        } else {
            (void)propid_fuse_accel(filter, entry->time_us, entry->value);
        }
        filter->delay.head = (uint8_t)(filter->delay.head + 1u >= PROPID_DELAY_SLOTS ? 0u : filter->delay.head + 1u);
        filter->delay.count--;
    }
}
#endif

#endif /* PROPID_DELAY_H */
