/*
 * Instruction-count harness for one filter step (benchmark, not a test).
 *
 * Flies a small float32 rigid-body simulation of a multirotor (Hummingbird-class,
 * diagonal inertia, per-rotor coefficients off the nominal, sums-of-sines rotor
 * speeds, gyro noise and bias), feeds the filter, and wraps every counted
 * gyro step in propid_count_begin()/propid_count_end(). count_step.sh runs the
 * ELF under qemu-system-arm with an instruction trace and counts the
 * instructions executed between the two markers (the step and all its callees;
 * not the rotor-speed push, not the simulation).
 *
 * Variants (each starts with propid_count_variant() and prints its label):
 * quad plus, quad X, hexa, octo, and the dense baseline (dense_ekf.c) on the
 * quad plus flight, flown side by side with propid on the same samples: only
 * the dense steps are counted, and the two estimates are compared at the end.
 *
 * Output (semihosting): per variant its label and the filter's status summary,
 * so a run whose steps were gated or repaired (cheaper or dearer paths) shows,
 * and the deepest stack a counted propid_push_gyro() call really used (painted
 * below the caller's stack pointer before the call, the deepest overwritten
 * word after it): a measurement of the paths this flight takes, beside the
 * call graph's worst case (firmware/toolchain/stack_report.py).
 *
 * -DCOUNT_STEP_GET_ESTIMATE: count propid_get_estimate() read after every step
 * (a controller reading the estimate at the gyro rate) instead of the step, and
 * print a hash of every estimate read (estimate_bits): two builds that give the
 * same estimates, bit for bit, print the same value.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "dense_ekf.h"
#include "propid/propid.h"
#include "semihosting.h"

#define WARMUP_STEPS 400u   /* let the filter settle (first samples collapse P) */
#define COUNTED_STEPS 200u
/* The dense baseline costs ~30x more to trace: fewer steps (same sequence). */
#define DENSE_WARMUP_STEPS 100u
#define DENSE_COUNTED_STEPS 50u
#define RATE_FEEDBACK 20.0f /* rotor speed per body rate [(rad/s)/(rad/s)]: keeps the rates small */
#define GYRO_DT_US 2000u    /* 500 Hz gyro, rotor speeds pushed before every gyro sample */
#define MAX_ROTORS 8u

/* The markers: noinline and distinct, so the trace shows their addresses. */
__attribute__((noinline)) void propid_count_variant(uint32_t variant);
__attribute__((noinline)) void propid_count_begin(uint32_t variant);
__attribute__((noinline)) void propid_count_end(uint32_t variant);
__attribute__((noinline)) void propid_count_variant(uint32_t variant) { __asm__ volatile("" ::"r"(variant)); }
__attribute__((noinline)) void propid_count_begin(uint32_t variant) { __asm__ volatile("" ::"r"(variant)); }
__attribute__((noinline)) void propid_count_end(uint32_t variant) { __asm__ volatile("" ::"r"(variant)); }

/* The measured stack of a call: STACK_WINDOW bytes below the caller's stack
 * pointer painted before it (all but the painting function's own frame and a
 * margin, below any call chain worth measuring), scanned after it. */
#define STACK_WINDOW 2048u
#define STACK_PAINT 0x5AC4C0DEu
static inline uintptr_t stack_pointer(void)
{
    uintptr_t sp;
    __asm__ volatile("mov %0, sp" : "=r"(sp));
    return sp;
}
static __attribute__((noinline)) void stack_paint_below(uintptr_t top)
{
    const uintptr_t own = stack_pointer();
    for (volatile uint32_t *word = (volatile uint32_t *)(top - STACK_WINDOW); (uintptr_t)word + 64u < own; ++word) {
        *word = STACK_PAINT;
    }
}
static __attribute__((noinline)) uint32_t stack_used_below(uintptr_t top)
{
    const volatile uint32_t *word = (const volatile uint32_t *)(top - STACK_WINDOW);
    while ((uintptr_t)word < top && *word == STACK_PAINT) {
        ++word;
    }
    return (uint32_t)(top - (uintptr_t)word);
}

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

/* x >= 0 with 6 significant digits as d.ddddde[-]XX (no printf on the target). */
static void put_sci(float x)
{
    int exponent = 0;
    if (x > 0.0f) {
        while (x >= 10.0f) {
            x /= 10.0f;
            exponent++;
        }
        while (x < 1.0f) {
            x *= 10.0f;
            exponent--;
        }
    }
    uint32_t digits = (uint32_t)(x * 100000.0f + 0.5f);
    put_uint(digits / 100000u);
    propid_qemu_putc('.');
    uint32_t frac = digits % 100000u;
    for (uint32_t div = 10000u; div > 0u; div /= 10u) {
        propid_qemu_putc((char)('0' + (frac / div) % 10u));
    }
    propid_qemu_putc('e');
    if (exponent < 0) {
        propid_qemu_putc('-');
        exponent = -exponent;
    }
    put_uint((uint32_t)exponent);
}

/* FNV-1a hash of n floats' bit patterns: two builds that end the flight with the
 * same state and covariance, bit for bit, print the same value. */
static uint32_t hash_bits(const float *values, uint32_t n)
{
    uint32_t hash = 2166136261u;
    for (uint32_t k = 0; k < n; ++k) {
        uint32_t bits;
        memcpy(&bits, &values[k], sizeof(bits));
        for (uint32_t byte = 0; byte < 4u; ++byte) {
            hash = (hash ^ ((bits >> (8u * byte)) & 0xFFu)) * 16777619u;
        }
    }
    return hash;
}

#ifdef COUNT_STEP_GET_ESTIMATE
/* The same hash continued over n bytes (an estimate: zeroed whole, padding included,
 * by propid_get_estimate). */
static uint32_t hash_more(uint32_t hash, const void *data, uint32_t n)
{
    const uint8_t *byte = data;
    for (uint32_t k = 0; k < n; ++k) {
        hash = (hash ^ byte[k]) * 16777619u;
    }
    return hash;
}
#endif

static propid_filter_t filter;
static propid_filter_t dense_model; /* the dense baseline's model and bookkeeping */
static dense_ekf_t dense;

/* Largest |dense - propid| over every state, in units of propid's std. */
static float dense_difference(void)
{
    float worst = 0.0f;
    const uint8_t n = filter.derived.state_count;
    for (uint8_t i = 0; i < n; ++i) {
        const float var = filter.core.cov[propid_cov_index(i, i)];
        const float diff = fabsf(dense.x[i] - filter.core.state[i]) / sqrtf(var);
        worst = diff > worst ? diff : worst;
    }
    return worst;
}

/* One flight: `rotors` rotors evenly spaced from first_angle; with_dense: the
 * dense baseline is counted instead of propid (both fly). Optional model terms
 * and measurements are further variants of this function (a flag argument and
 * a row in main() with its label). */
static int fly(uint32_t variant, const char *label, uint8_t rotors, float first_angle, int with_dense)
{
    propid_count_variant(variant);
    propid_qemu_puts("variant ");
    propid_qemu_puts(label);
    propid_qemu_putc('\n');
    const float kf_nominal = 5.57e-6f;
    const float km_nominal = 1.36e-7f;
    const float jxx = 3.65e-3f, jyy = 3.68e-3f, jzz = 7.03e-3f;
    propid_config_t config;
    propid_config_default(&config);
    if (propid_config_set_symmetric(&config, rotors, 0.17f, first_angle, 1.0f, kf_nominal, km_nominal) !=
        PROPID_OK) {
        return 1;
    }
    propid_config_set_inertia_diag(&config, jxx, jyy, jzz);
#ifdef COUNT_STEP_DISTURBANCE
    /* -DCOUNT_STEP_DISTURBANCE: the three disturbance-torque states on. */
    config.disturbance_torque = 1u;
#endif
#ifdef COUNT_STEP_ROTOR_INERTIA
    /* -DCOUNT_STEP_ROTOR_INERTIA=J: every rotor spins with inertia J [kg m^2]
     * (yaw reaction and gyroscopic terms in the prediction). */
    for (uint32_t i = 0; i < rotors; ++i) {
        config.rotor_inertia[i] = COUNT_STEP_ROTOR_INERTIA;
    }
#endif
#ifdef COUNT_STEP_AERO_DAMPING
    /* -DCOUNT_STEP_AERO_DAMPING=D: an aerodynamic rate damping D [N m s/rad] on every axis
     * (docs/math.md §17; the general step's rate entries). */
    for (uint32_t a = 0; a < 3u; ++a) {
        config.aero_damping[a] = COUNT_STEP_AERO_DAMPING;
    }
#endif
#ifdef COUNT_STEP_INPUT_NOISE
    /* -DCOUNT_STEP_INPUT_NOISE=S: rotor-speed input error of std S [rad/s] in the rate
     * process noise (docs/math.md §14), correlated over 10 ms. */
    config.rotor_speed_noise = COUNT_STEP_INPUT_NOISE;
    config.rotor_speed_noise_time = 0.01f;
#ifdef COUNT_STEP_INPUT_COMPENSATION
    /* and -DCOUNT_STEP_INPUT_COMPENSATION: its errors-in-variables compensation. */
    config.input_error_compensation = 1u;
#endif
#endif
#ifdef COUNT_STEP_REPORT_TIMING
    /* -DCOUNT_STEP_REPORT_TIMING=T: the rotor report's timing error of std T [s] in the rate
     * process noise (docs/math.md §14, "The report's timing"). */
    config.rotor_timing_error = COUNT_STEP_REPORT_TIMING;
#endif
#ifdef COUNT_STEP_ACCEL
    /* -DCOUNT_STEP_ACCEL: the accelerometer's z bias state on (a 30 g vehicle; the counted
     * flight pushes no accelerometer sample: the gyro step with one more state). */
    config.mass = 0.03f;
#ifdef COUNT_STEP_ACCEL_ERROR
    /* and -DCOUNT_STEP_ACCEL_ERROR: the accelerometer row's model-error state, whose
     * Gauss-Markov decay every gyro step's prediction applies (docs/math.md §9). */
    config.accel_error_std = 0.03f;
    config.accel_error_time = 10.0f;
#endif
#endif
#ifdef COUNT_STEP_DELAY_US
    /* -DCOUNT_STEP_DELAY_US=D: the telemetry delay D held by the filter; each counted
     * step is then the rotor push and the gyro push together (a held sample is fused
     * in either): compare with D = 0, counted the same way. */
    config.rotor_delay_us = COUNT_STEP_DELAY_US;
#endif
    if (propid_init(&filter, &config) != PROPID_OK ||
        (with_dense && propid_init(&dense_model, &config) != PROPID_OK)) {
        return 1;
    }
    const float kf_scale[MAX_ROTORS] = {1.10f, 0.92f, 1.05f, 0.88f, 0.95f, 1.07f, 0.97f, 1.03f};
    const float km_scale[MAX_ROTORS] = {0.90f, 1.12f, 1.04f, 0.95f, 1.08f, 0.93f, 1.01f, 0.97f};
    const float bias[3] = {0.01f, -0.02f, 0.015f};
    const float gyro_std = 0.011f;
    /* Hover speed of the rotor count (same thrust to weight for every variant). */
    const float hover = 900.0f * sqrtf(4.0f / (float)rotors);
    float rate[3] = {0.0f, 0.0f, 0.0f};
    const float dt = (float)GYRO_DT_US * 1.0e-6f;
    uint64_t t_us = 1000u;
    int errors = 0;
    uint32_t stack_max = 0u; /* deepest stack of a counted propid_push_gyro() [B] */
#ifdef COUNT_STEP_GET_ESTIMATE
    uint32_t estimate_hash = 2166136261u;
#endif
    const uint32_t warmup = with_dense ? DENSE_WARMUP_STEPS : WARMUP_STEPS;
    const uint32_t total = warmup + (with_dense ? DENSE_COUNTED_STEPS : COUNTED_STEPS);
    const float arm = 0.17f;
    for (uint32_t step = 0; step < total; ++step) {
        const float t = (float)step * dt;
        /* Hover plus differential sines (rad/s), different per rotor, plus a
         * rate feedback through the mixer, as a flight controller's rate loop
         * does: the body rates stay at a few rad/s on every frame. */
        float speed[MAX_ROTORS];
        for (uint32_t i = 0; i < rotors; ++i) {
            const float phase = 1.3f * (float)i;
            const float *r = config.rotor[i].position_m;
            const float feedback = -RATE_FEEDBACK * (rate[0] * r[1] / arm - rate[1] * r[0] / arm +
                                                     rate[2] * config.rotor[i].yaw_sign);
            speed[i] = hover + 60.0f * sinf(7.0f * t + phase) + 35.0f * sinf(23.0f * t + 2.0f * phase) +
                       feedback;
        }
        /* Torque from the true coefficients (same geometry as the filter). */
        float torque[3] = {0.0f, 0.0f, 0.0f};
        for (uint32_t i = 0; i < rotors; ++i) {
            const float u = speed[i] * speed[i];
            const float kf = kf_scale[i] * kf_nominal, km = km_scale[i] * km_nominal;
            torque[0] += config.rotor[i].position_m[1] * kf * u;
            torque[1] -= config.rotor[i].position_m[0] * kf * u;
            torque[2] += config.rotor[i].yaw_sign * km * u;
        }
        /* Weak rate damping keeps the simulation bounded (unmodelled for the filter). */
        const float momentum[3] = {jxx * rate[0], jyy * rate[1], jzz * rate[2]};
        const float gyroscopic[3] = {rate[1] * momentum[2] - rate[2] * momentum[1],
                                     rate[2] * momentum[0] - rate[0] * momentum[2],
                                     rate[0] * momentum[1] - rate[1] * momentum[0]};
        const float inertia[3] = {jxx, jyy, jzz};
#ifdef COUNT_STEP_DELAY_US
        if (!with_dense && step >= warmup) {
            propid_count_begin(variant);
        }
#endif
        if (propid_push_rotor_speeds(&filter, t_us, speed, rotors) < 0 ||
            (with_dense && propid_push_rotor_speeds(&dense_model, t_us, speed, rotors) != PROPID_OK)) {
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
        const int counted = step >= warmup;
        if (with_dense) {
            /* The reference propid filter is not counted; the dense one is from
             * its second sample on (the first only anchors the time). */
            if (step == 0u) {
                if (propid_push_gyro(&dense_model, t_us, gyro) < 0) {
                    errors++;
                }
                dense_ekf_load(&dense, &dense_model);
            } else {
                if (counted) {
                    propid_count_begin(variant);
                }
                const int failed = dense_ekf_step(&dense, &dense_model, t_us, gyro);
                if (counted) {
                    propid_count_end(variant);
                }
                errors += failed != 0;
            }
            if (propid_push_gyro(&filter, t_us, gyro) < 0) {
                errors++;
            }
            continue;
        }
        const uintptr_t caller_sp = stack_pointer();
        if (counted) {
            stack_paint_below(caller_sp);
        }
#if !defined(COUNT_STEP_DELAY_US) && !defined(COUNT_STEP_GET_ESTIMATE)
        if (counted) {
            propid_count_begin(variant);
        }
#endif
        const propid_status_t status = propid_push_gyro(&filter, t_us, gyro);
        if (counted) {
#ifndef COUNT_STEP_GET_ESTIMATE
            propid_count_end(variant);
#endif
            const uint32_t used = stack_used_below(caller_sp);
            stack_max = used > stack_max ? used : stack_max;
        }
        if (status < 0) {
            errors++;
        }
#ifdef COUNT_STEP_GET_ESTIMATE
        if (counted) {
            propid_count_begin(variant);
        }
        propid_estimate_t estimate;
        const propid_status_t read = propid_get_estimate(&filter, &estimate);
        if (counted) {
            propid_count_end(variant);
        }
        errors += read != PROPID_OK;
        estimate_hash = hash_more(estimate_hash, &estimate, (uint32_t)sizeof(estimate));
#endif
    }
    propid_counters_t counters;
    (void)propid_get_counters(&filter, &counters);
    propid_qemu_puts(label);
    propid_qemu_puts(": accepted ");
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
    if (!with_dense) {
        propid_qemu_puts(" stack_used_push_gyro ");
        put_uint(stack_max);
        propid_qemu_puts(" final_state_bits ");
        put_uint(hash_bits(filter.core.state, PROPID_MAX_STATES) ^
                 hash_bits(filter.core.cov, PROPID_COV_SIZE));
#ifdef COUNT_STEP_GET_ESTIMATE
        propid_qemu_puts(" estimate_bits ");
        put_uint(estimate_hash);
#endif
    }
    propid_qemu_putc('\n');
    if (with_dense) {
        /* The same estimates: every state within a small fraction of its std. */
        propid_qemu_puts("dense-vs-propid max_state_diff_in_std ");
        put_sci(dense_difference());
        propid_qemu_putc('\n');
    }
    return errors != 0;
}

int main(void)
{
    int failed = 0;
    failed |= fly(0u, "quad_plus", 4u, 0.0f, 0);
    failed |= fly(1u, "quad_x", 4u, 0.78539816f, 0);
#if PROPID_MAX_ROTORS >= 6
    failed |= fly(2u, "hexa", 6u, 0.0f, 0);
#endif
#if PROPID_MAX_ROTORS >= 8
    failed |= fly(3u, "octo", 8u, 0.0f, 0);
#endif
#ifndef COUNT_STEP_NO_DENSE /* -DCOUNT_STEP_NO_DENSE: the filter's variants only (faster) */
    failed |= fly(4u, "dense_quad_plus", 4u, 0.0f, 1);
#endif
    return failed;
}
