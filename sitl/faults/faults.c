/* Fault injection between sensors and filter (faults.h, docs/sitl.md "Faults"). */
#include "faults.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Burst length of stuck and stale faults [samples of their stream]. */
#define SITL_FAULT_BURST 50

static const char *const fault_names[SITL_FAULT_COUNT] = {
    "esc_dropout", "esc_spike", "esc_stuck", "esc_stale",
    "gyro_spike", "gyro_saturation", "gyro_stuck",
    "time_jitter", "time_repeat", "time_backward", "time_jump",
    "rotor_loss",
};

const char *sitl_fault_name(sitl_fault_class_t fault)
{
    return (fault >= 0 && fault < SITL_FAULT_COUNT) ? fault_names[fault] : "?";
}

void sitl_faults_names(char *out, int out_size, const char *separator)
{
    int used = snprintf(out, (size_t)out_size, "none");
    for (int k = 0; k < SITL_FAULT_COUNT && used >= 0 && used < out_size; ++k) {
        used += snprintf(out + used, (size_t)(out_size - used), "%s%s", separator, fault_names[k]);
    }
}

int sitl_faults_parse(sitl_fault_config_t *config, const char *text, char *err, int err_size)
{
    if (strcmp(text, "none") == 0) {
        memset(config, 0, sizeof(*config));
        return 0;
    }
    const char *eq = strchr(text, '=');
    const size_t name_len = eq != NULL ? (size_t)(eq - text) : strlen(text);
    for (int k = 0; k < SITL_FAULT_COUNT; ++k) {
        if (strlen(fault_names[k]) != name_len || strncmp(text, fault_names[k], name_len) != 0) {
            continue;
        }
        if (eq == NULL) {
            snprintf(err, (size_t)err_size, "--fault %s needs =RATE", fault_names[k]);
            return -1;
        }
        char *end = NULL;
        const double rate = strtod(eq + 1, &end);
        const double hi = (k == SITL_FAULT_TIME_JITTER || k == SITL_FAULT_ROTOR_LOSS) ? 1e6 : 1.0;
        if (end == eq + 1 || *end != '\0' || !isfinite(rate) || rate < 0.0 || rate > hi) {
            snprintf(err, (size_t)err_size, "--fault %s: '%s' is not a number in [0, %g]", fault_names[k],
                     eq + 1, hi);
            return -1;
        }
        config->rate[k] = rate;
        config->enabled = 1;
        return 0;
    }
    snprintf(err, (size_t)err_size, "--fault: unknown fault '%s'", text);
    return -1;
}

void sitl_faults_init(sitl_faults_t *faults, const sitl_fault_config_t *config, uint64_t seed)
{
    memset(faults, 0, sizeof(*faults));
    faults->config = *config;
    sitl_rng_init(&faults->rng, seed, 0xfa17u);
}

static int happens(sitl_faults_t *f, sitl_fault_class_t k)
{
    return f->config.rate[k] > 0.0 && sitl_rng_uniform(&f->rng) < f->config.rate[k];
}

/* Clock faults common to both streams: jitter, repeats, backward steps, jumps. */
static void fault_time(sitl_faults_t *f, uint64_t *time_us, uint64_t *last_us)
{
    if (happens(f, SITL_FAULT_TIME_JUMP)) {
        f->clock_offset_us += 1000000u; /* 1 s: beyond any max_gyro_gap_us default */
        f->injected[SITL_FAULT_TIME_JUMP]++;
    }
    uint64_t t = *time_us + f->clock_offset_us;
    if (f->config.rate[SITL_FAULT_TIME_JITTER] > 0.0) {
        const double shift = f->config.rate[SITL_FAULT_TIME_JITTER] * sitl_rng_normal(&f->rng);
        const int64_t step = (int64_t)llround(shift);
        t = (step < 0 && (uint64_t)(-step) > t) ? 0u : (uint64_t)((int64_t)t + step);
        f->injected[SITL_FAULT_TIME_JITTER]++;
    }
    if (*last_us != 0u && happens(f, SITL_FAULT_TIME_REPEAT)) {
        t = *last_us;
        f->injected[SITL_FAULT_TIME_REPEAT]++;
    } else if (*last_us > 5000u && happens(f, SITL_FAULT_TIME_BACKWARD)) {
        t = *last_us - 5000u;
        f->injected[SITL_FAULT_TIME_BACKWARD]++;
    }
    *last_us = t;
    *time_us = t;
}

int sitl_faults_esc(sitl_faults_t *f, uint64_t *time_us, float *speed, int rotor_count)
{
    if (!f->config.enabled) {
        return 1;
    }
    if (f->esc_stale_left > 0) {
        f->esc_stale_left--;
        return 0;
    }
    if (happens(f, SITL_FAULT_ESC_STALE)) {
        f->esc_stale_left = SITL_FAULT_BURST;
        f->injected[SITL_FAULT_ESC_STALE]++;
        return 0;
    }
    if (happens(f, SITL_FAULT_ESC_DROPOUT)) {
        f->injected[SITL_FAULT_ESC_DROPOUT]++;
        return 0;
    }
    fault_time(f, time_us, &f->last_esc_us);
    if (f->esc_stuck_left > 0) {
        f->esc_stuck_left--;
        memcpy(speed, f->esc_stuck_value, (size_t)rotor_count * sizeof(float));
    } else if (happens(f, SITL_FAULT_ESC_STUCK)) {
        f->esc_stuck_left = SITL_FAULT_BURST;
        memcpy(f->esc_stuck_value, speed, (size_t)rotor_count * sizeof(float));
        f->injected[SITL_FAULT_ESC_STUCK]++;
    }
    if (happens(f, SITL_FAULT_ESC_SPIKE)) {
        /* A CRC-failed frame decoded as a speed: anything up to 20 000 rad/s. */
        const int rotor = (int)(sitl_rng_next(&f->rng) % (uint64_t)rotor_count);
        speed[rotor] = (float)sitl_rng_range(&f->rng, 0.0, 20000.0);
        f->injected[SITL_FAULT_ESC_SPIKE]++;
    }
    return 1;
}

void sitl_faults_gyro(sitl_faults_t *f, uint64_t *time_us, float gyro[3], double range)
{
    if (!f->config.enabled) {
        return;
    }
    fault_time(f, time_us, &f->last_gyro_us);
    if (f->gyro_stuck_left > 0) {
        f->gyro_stuck_left--;
        gyro[f->gyro_stuck_axis] = f->gyro_stuck_value;
    } else if (happens(f, SITL_FAULT_GYRO_STUCK)) {
        f->gyro_stuck_left = SITL_FAULT_BURST;
        f->gyro_stuck_axis = (int)(sitl_rng_next(&f->rng) % 3u);
        f->gyro_stuck_value = gyro[f->gyro_stuck_axis];
        f->injected[SITL_FAULT_GYRO_STUCK]++;
    }
    if (happens(f, SITL_FAULT_GYRO_SPIKE)) {
        const int axis = (int)(sitl_rng_next(&f->rng) % 3u);
        gyro[axis] += (float)sitl_rng_range(&f->rng, -20.0, 20.0);
        f->injected[SITL_FAULT_GYRO_SPIKE]++;
    }
    if (happens(f, SITL_FAULT_GYRO_SATURATION)) {
        const int axis = (int)(sitl_rng_next(&f->rng) % 3u);
        const double full_scale = range > 0.0 ? range : 34.9;
        gyro[axis] = (float)((gyro[axis] < 0.0f ? -1.0 : 1.0) * 1.01 * full_scale);
        f->injected[SITL_FAULT_GYRO_SATURATION]++;
    }
}

int sitl_faults_rotor_loss_due(const sitl_faults_t *f, double t)
{
    const double at = f->config.rate[SITL_FAULT_ROTOR_LOSS];
    return !f->rotor_lost && at > 0.0 && !(t < at);
}

int sitl_faults_rotor_loss_now(sitl_faults_t *f, double t)
{
    const double at = f->config.rate[SITL_FAULT_ROTOR_LOSS];
    if (f->rotor_lost || !(at > 0.0) || t < at) {
        return 0;
    }
    f->rotor_lost = 1;
    f->injected[SITL_FAULT_ROTOR_LOSS]++;
    return 1;
}
