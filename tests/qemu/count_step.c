/*
 * Instruction-count harness for one filter step (benchmark, not a test).
 *
 * Flies a small float32 rigid-body simulation of a quad (plus frame and X frame,
 * Hummingbird-class, diagonal inertia, per-rotor coefficients off the nominal,
 * sums-of-sines rotor speeds, gyro noise and bias), feeds the filter, and wraps
 * every counted propid_push_gyro() call in propid_count_begin()/propid_count_end().
 * count_step.sh runs the ELF under qemu-system-arm with an instruction trace and
 * counts the instructions executed between the two markers (the step and all
 * its callees; not the rotor-speed push, not the simulation).
 *
 * Output (semihosting): one line per variant with the filter's status summary,
 * so a run whose steps were gated or repaired (cheaper or dearer paths) shows.
 */
#include <math.h>
#include <stdint.h>

#include "propid/propid.h"
#include "semihosting.h"

#define WARMUP_STEPS 400u   /* let the filter settle (first samples collapse P) */
#define COUNTED_STEPS 200u
#define GYRO_DT_US 2000u    /* 500 Hz gyro, rotor speeds pushed before every gyro sample */

/* The markers: noinline and distinct, so the trace shows their addresses. */
__attribute__((noinline)) void propid_count_begin(uint32_t variant);
__attribute__((noinline)) void propid_count_end(uint32_t variant);
__attribute__((noinline)) void propid_count_begin(uint32_t variant) { __asm__ volatile("" ::"r"(variant)); }
__attribute__((noinline)) void propid_count_end(uint32_t variant) { __asm__ volatile("" ::"r"(variant)); }

static uint32_t rng_state = 12345u;
static float noise(void) /* uniform in [-1, 1] */
{
    rng_state = rng_state * 1664525u + 1013904223u;
    return (float)(rng_state >> 8) * (2.0f / 16777216.0f) - 1.0f;
}

static void put_uint(uint32_t value)
{
    char digits[12];
    int count = 0;
    do {
        digits[count++] = (char)('0' + value % 10u);
        value /= 10u;
    } while (value != 0u && count < 12);
    while (count > 0) {
        propid_qemu_putc(digits[--count]);
    }
}

static propid_filter_t filter;

static int fly(uint32_t variant, float first_angle)
{
    const float kf_nominal = 5.57e-6f;
    const float km_nominal = 1.36e-7f;
    const float jxx = 3.65e-3f, jyy = 3.68e-3f, jzz = 7.03e-3f;
    propid_config_t config;
    propid_config_default(&config);
    if (propid_config_set_symmetric(&config, 4u, 0.17f, first_angle, 1.0f, kf_nominal, km_nominal) !=
        PROPID_OK) {
        return 1;
    }
    propid_config_set_inertia_diag(&config, jxx, jyy, jzz);
    if (propid_init(&filter, &config) != PROPID_OK) {
        return 1;
    }
    const float kf_true[4] = {1.10f * kf_nominal, 0.92f * kf_nominal, 1.05f * kf_nominal, 0.88f * kf_nominal};
    const float km_true[4] = {0.90f * km_nominal, 1.12f * km_nominal, 1.04f * km_nominal, 0.95f * km_nominal};
    const float bias[3] = {0.01f, -0.02f, 0.015f};
    const float gyro_std = 0.011f;
    float rate[3] = {0.0f, 0.0f, 0.0f};
    const float dt = (float)GYRO_DT_US * 1.0e-6f;
    uint64_t t_us = 1000u;
    int errors = 0;
    for (uint32_t step = 0; step < WARMUP_STEPS + COUNTED_STEPS; ++step) {
        const float t = (float)step * dt;
        /* Hover plus differential sines (rad/s), different per rotor. */
        float speed[4];
        for (uint32_t i = 0; i < 4u; ++i) {
            const float phase = 1.3f * (float)i;
            speed[i] = 900.0f + 60.0f * sinf(7.0f * t + phase) + 35.0f * sinf(23.0f * t + 2.0f * phase);
        }
        /* Torque from the true coefficients (same geometry as the filter). */
        float torque[3] = {0.0f, 0.0f, 0.0f};
        for (uint32_t i = 0; i < 4u; ++i) {
            const float u = speed[i] * speed[i];
            torque[0] += config.rotor[i].position_m[1] * kf_true[i] * u;
            torque[1] -= config.rotor[i].position_m[0] * kf_true[i] * u;
            torque[2] += config.rotor[i].yaw_sign * km_true[i] * u;
        }
        /* Weak rate damping keeps the simulation bounded (unmodelled for the filter). */
        const float momentum[3] = {jxx * rate[0], jyy * rate[1], jzz * rate[2]};
        const float gyroscopic[3] = {rate[1] * momentum[2] - rate[2] * momentum[1],
                                     rate[2] * momentum[0] - rate[0] * momentum[2],
                                     rate[0] * momentum[1] - rate[1] * momentum[0]};
        const float inertia[3] = {jxx, jyy, jzz};
        if (propid_push_rotor_speeds(&filter, t_us, speed, 4u) != PROPID_OK) {
            errors++;
        }
        t_us += GYRO_DT_US;
        for (uint32_t a = 0; a < 3u; ++a) {
            rate[a] += dt * ((torque[a] - gyroscopic[a]) / inertia[a] - 0.5f * rate[a]);
        }
        float gyro[3];
        for (uint32_t a = 0; a < 3u; ++a) {
            gyro[a] = rate[a] + bias[a] + gyro_std * 1.7f * noise();
        }
        const int counted = step >= WARMUP_STEPS;
        if (counted) {
            propid_count_begin(variant);
        }
        const propid_status_t status = propid_push_gyro(&filter, t_us, gyro);
        if (counted) {
            propid_count_end(variant);
        }
        if (status < 0) {
            errors++;
        }
    }
    propid_counters_t counters;
    (void)propid_get_counters(&filter, &counters);
    propid_qemu_puts(variant == 0u ? "plus: " : "x:    ");
    propid_qemu_puts("accepted ");
    put_uint(counters.gyro_accepted);
    propid_qemu_puts(" gated ");
    put_uint(counters.axis_gated[0] + counters.axis_gated[1] + counters.axis_gated[2]);
    propid_qemu_puts(" reopened ");
    put_uint(counters.gate_reopened);
    propid_qemu_puts(" repairs ");
    put_uint(counters.cov_repairs);
    propid_qemu_puts(" clamps ");
    put_uint(counters.state_clamps);
    propid_qemu_puts(" rejected ");
    put_uint((uint32_t)errors);
    propid_qemu_putc('\n');
    return errors != 0;
}

int main(void)
{
    int failed = fly(0u, 0.0f);                       /* plus frame */
    failed |= fly(1u, 0.78539816f);                   /* X frame */
    return failed;
}
