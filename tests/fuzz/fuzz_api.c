/*
 * libFuzzer harness of the firmware's public API (make fuzz, docs/reliability.md).
 *
 * The input bytes are decoded into a configuration (a valid base, symmetric or
 * with rotors placed one by one, with fields overwritten by fuzzed values,
 * some of them absurd) and a stream of calls:
 * rotor speeds, gyro samples (with fuzzed timestamps: steps, repeats,
 * backward steps, jumps), resync, reset, reset_rotor, estimate. After every
 * call the harness checks, and aborts (a crash for libFuzzer) when one fails:
 *   - a rejected call (status < 0) left config, derived quantities, core state
 *     and covariance byte-identical;
 *   - estimates, standard deviations and innovation ratios are finite;
 *   - every variance is positive and finite, the state finite;
 *   - an accepted gyro sample left P positive definite (Cholesky in double),
 *     counted in `cholesky_failures` rather than aborting when
 *     PROPID_FUZZ_CHOLESKY_ABORT is 0 (run_fuzz.sh builds it so).
 * Run under ASan + UBSan (the Makefile builds it so).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "propid/propid.h"
#include "../firmware/cov_positive_definite.h"

#ifndef PROPID_FUZZ_CHOLESKY_ABORT
#define PROPID_FUZZ_CHOLESKY_ABORT 1
#endif

typedef struct {
    const uint8_t *data;
    size_t size;
    size_t pos;
} reader_t;

static uint8_t read_u8(reader_t *r)
{
    return r->pos < r->size ? r->data[r->pos++] : 0u;
}

static uint32_t read_u32(reader_t *r)
{
    uint32_t v = 0u;
    for (int i = 0; i < 4; ++i) {
        v |= (uint32_t)read_u8(r) << (8 * i);
    }
    return v;
}

static float raw_float(reader_t *r)
{
    const uint32_t bits = read_u32(r);
    float f;
    memcpy(&f, &bits, sizeof(f));
    return f;
}

/* A value: mostly inside [lo, hi], sometimes a raw bit pattern (NaN, Inf,
 * huge, denormal, negative). */
static float fuzz_value(reader_t *r, float lo, float hi)
{
    const uint8_t mode = read_u8(r);
    if (mode < 224u) {
        const float unit = (float)read_u8(r) / 255.0f;
        return lo + (hi - lo) * unit;
    }
    return raw_float(r);
}

/* A config field: kept (most often), scaled by a power of ten, or fuzzed. */
static void fuzz_field(reader_t *r, float *field)
{
    const uint8_t mode = read_u8(r);
    if (mode < 160u) {
        return;
    }
    if (mode < 232u) {
        const int exponent = (int)(mode % 13u) - 6;
        *field *= powf(10.0f, (float)exponent);
        return;
    }
    *field = raw_float(r);
}

/* Planar positions and spin directions of every rotor: angles first, then
 * signed radii (128: the centre; 192: the arm; 64: the arm on the opposite
 * side), then a mask that flips the symmetric frame's yaw signs. A run of
 * equal angle bytes (a common mutation) puts the rotors on one line through
 * the centre, on both sides when their radii differ in sign. Degenerate frames
 * (rotors on a line, together, at the centre) give torque combinations the
 * gyro cannot tell apart: the rounding of the prediction's cancelling terms is
 * what the covariance has to survive (docs/reliability.md). */
static void place_rotors(reader_t *r, propid_config_t *config, uint8_t rotors, float arm)
{
    float angle[PROPID_MAX_ROTORS];
    for (uint8_t i = 0; i < rotors; ++i) {
        angle[i] = 6.2831853f * (float)read_u8(r) / 256.0f;
    }
    for (uint8_t i = 0; i < rotors; ++i) {
        const float radius = arm * ((float)read_u8(r) - 128.0f) / 64.0f; /* -2 to +2 arms */
        config->rotor[i].position_m[0] = radius * cosf(angle[i]);
        config->rotor[i].position_m[1] = radius * sinf(angle[i]);
    }
    const uint8_t flips = read_u8(r);
    for (uint8_t i = 0; i < rotors; ++i) {
        if (flips & (1u << i)) {
            config->rotor[i].yaw_sign = -config->rotor[i].yaw_sign;
        }
    }
}

/* Input layout: rotor count, arm, plus/X, geometry (< 128: the symmetric
 * frame; else place_rotors' bytes), the fuzzed fields, the guards; then the
 * calls. tests/fuzz/reencode_corpus.py converted the seed corpus from the
 * layout without the geometry byte. */
static void make_config(reader_t *r, propid_config_t *config)
{
    propid_config_default(config);
    const uint8_t rotors = (uint8_t)(1u + read_u8(r) % PROPID_MAX_ROTORS);
    const float arm = 0.05f + 0.3f * (float)read_u8(r) / 255.0f;
    const float angle = (read_u8(r) & 1u) ? 0.7853982f : 0.0f;
    if (propid_config_set_symmetric(config, rotors, arm, angle, 1.0f, 5.57e-6f, 1.36e-7f) != PROPID_OK) {
        abort();
    }
    if (read_u8(r) >= 128u) {
        place_rotors(r, config, rotors, arm);
    }
    propid_config_set_inertia_diag(config, 3.65e-3f, 3.68e-3f, 7.03e-3f);
    float *fields[] = {
        &config->rate_std0, &config->thrust_coeff_rel_std0, &config->drag_coeff_rel_std0,
        &config->gyro_bias_std0, &config->gyro_noise_density, &config->gyro_sample_rate_hz,
        &config->rate_process_noise, &config->thrust_coeff_rel_walk, &config->drag_coeff_rel_walk,
        &config->gyro_bias_walk, &config->gate_sigma, &config->max_rotor_speed, &config->gyro_range,
        &config->coeff_rel_min, &config->coeff_rel_max, &config->converged_rel_std,
        &config->inertia[0][0], &config->inertia[1][1], &config->inertia[2][2], &config->inertia[0][1],
        &config->rotor[0].thrust_coeff_nominal, &config->rotor[0].drag_coeff_nominal,
        &config->rotor[0].position_m[2],
    };
    for (size_t i = 0; i < sizeof fields / sizeof fields[0]; ++i) {
        fuzz_field(r, fields[i]);
    }
    config->inertia[1][0] = config->inertia[0][1];
    const uint8_t guards = read_u8(r);
    if (guards & 1u) {
        config->gate_max_consecutive = (uint16_t)read_u32(r);
    }
    if (guards & 2u) {
        config->rotor_stale_us = read_u32(r);
    }
    if (guards & 4u) {
        config->max_gyro_gap_us = read_u32(r);
    }
    if (guards & 8u) {
        config->rotor_count = read_u8(r);
    }
    if (guards & 16u) {
        config->rotor[read_u8(r) % PROPID_MAX_ROTORS].yaw_sign = raw_float(r);
    }
}

/* Time step of a stream: usual periods, repeats, backward steps, jumps. */
static uint64_t next_time(reader_t *r, uint64_t now)
{
    const uint8_t mode = read_u8(r);
    if (mode < 200u) {
        return now + 1u + (uint64_t)read_u8(r) * 40u;
    }
    if (mode < 215u) {
        return now;
    }
    if (mode < 230u) {
        const uint64_t back = (uint64_t)read_u8(r) * 1000u;
        return back < now ? now - back : 0u;
    }
    if (mode < 245u) {
        return now + (uint64_t)read_u32(r);
    }
    return ((uint64_t)read_u32(r) << 32) | read_u32(r);
}

static int finite_all(const float *values, uint32_t count)
{
    for (uint32_t i = 0; i < count; ++i) {
        if (!isfinite(values[i])) {
            return 0;
        }
    }
    return 1;
}

static void fail(const char *what)
{
    fprintf(stderr, "propid fuzz check failed: %s\n", what);
    abort();
}

static uint64_t cholesky_checks;
static uint64_t cholesky_failures;

static void check_invariants(const propid_filter_t *filter)
{
    propid_estimate_t e;
    if (propid_get_estimate(filter, &e) != PROPID_OK) {
        fail("get_estimate on an initialised filter");
    }
    const uint32_t rotors = e.rotor_count;
    if (!finite_all(e.body_rate, 3u) || !finite_all(e.body_rate_std, 3u) || !finite_all(e.gyro_bias, 3u) ||
        !finite_all(e.gyro_bias_std, 3u) || !finite_all(e.thrust_coeff, rotors) ||
        !finite_all(e.thrust_coeff_std, rotors) || !finite_all(e.drag_coeff, rotors) ||
        !finite_all(e.drag_coeff_std, rotors) || !finite_all(e.innovation, 3u)) {
        fail("non-finite estimate");
    }
    if (!finite_all(e.innovation_test_ratio, 3u)) {
        fail("non-finite innovation_test_ratio");
    }
    const uint8_t n = filter->derived.state_count;
    for (uint8_t i = 0; i < n; ++i) {
        if (!isfinite(filter->core.state[i])) {
            fail("non-finite state");
        }
        const float p = filter->core.cov[propid_cov_index(i, i)];
        if (!(p > 0.0f) || !isfinite(p)) {
            fail("variance not positive and finite");
        }
        for (uint8_t j = (uint8_t)(i + 1u); j < n; ++j) {
            if (!isfinite(filter->core.cov[propid_cov_index(i, j)])) {
                fail("non-finite covariance");
            }
        }
    }
}

static void check_rejection(propid_status_t status, const propid_filter_t *before, const propid_filter_t *after)
{
    if (status >= 0) {
        return;
    }
    if (memcmp(&before->config, &after->config, sizeof(after->config)) != 0 ||
        memcmp(&before->derived, &after->derived, sizeof(after->derived)) != 0 ||
        memcmp(&before->core, &after->core, sizeof(after->core)) != 0 || before->magic != after->magic) {
        fail("rejected call changed the filter");
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerInitialize(int *argc, char ***argv);

/* One summary line at exit, read by tests/fuzz/run_fuzz.sh. */
static void print_stats(void)
{
    fprintf(stderr, "propid-fuzz: cholesky_checks %llu cholesky_failures %llu\n",
            (unsigned long long)cholesky_checks, (unsigned long long)cholesky_failures);
}

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    atexit(print_stats);
    return 0;
}
#ifdef PROPID_FUZZ_DEBUG
void propid_fuzz_debug_dump(const propid_filter_t *before, const propid_filter_t *after);
#endif

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static propid_filter_t filter;
    static propid_filter_t before;
    reader_t r = {data, size, 0u};
    propid_config_t config;
    make_config(&r, &config);
    memset(&filter, 0, sizeof(filter));
    if (propid_init(&filter, &config) != PROPID_OK) {
        if (filter.magic != 0u) {
            fail("failed init left the filter initialised");
        }
        return 0;
    }
    const uint8_t rotor_count = config.rotor_count;
    const float speed_max = config.max_rotor_speed;
    const float gyro_max = config.gyro_range;
    uint64_t rotor_time = 1000000u;
    uint64_t gyro_time = 1000000u;
    for (uint32_t call = 0; call < 4096u && r.pos < r.size; ++call) {
        const uint8_t op = read_u8(&r);
        before = filter;
        propid_status_t status = PROPID_OK;
        int gyro_call = 0;
        if (op < 110u) {
            float speeds[PROPID_MAX_ROTORS];
            const float base = fuzz_value(&r, 0.0f, 0.8f * speed_max);
            for (uint8_t i = 0; i < PROPID_MAX_ROTORS; ++i) {
                speeds[i] = (read_u8(&r) < 240u) ? base * (0.8f + 0.4f * (float)read_u8(&r) / 255.0f)
                                                 : fuzz_value(&r, 0.0f, 1.2f * speed_max);
            }
            rotor_time = next_time(&r, rotor_time);
            const uint8_t count = (read_u8(&r) < 250u) ? rotor_count : read_u8(&r);
            status = propid_push_rotor_speeds(&filter, rotor_time, speeds, count);
        } else if (op < 235u) {
            float gyro[3];
            const float scale = (read_u8(&r) < 200u) ? 0.1f * gyro_max : gyro_max;
            for (uint8_t a = 0; a < 3u; ++a) {
                gyro[a] = fuzz_value(&r, -scale, scale);
            }
            gyro_time = next_time(&r, gyro_time);
            status = propid_push_gyro(&filter, gyro_time, gyro);
            gyro_call = 1;
        } else if (op < 245u) {
            gyro_time = next_time(&r, gyro_time);
            status = propid_resync(&filter, gyro_time);
        } else if (op < 250u) {
            status = propid_reset_rotor(&filter, read_u8(&r));
        } else if (op < 252u) {
            status = propid_reset(&filter);
        } else {
            propid_estimate_t e;
            status = propid_get_estimate(&filter, &e);
        }
        check_rejection(status, &before, &filter);
        check_invariants(&filter);
        if (gyro_call && status >= 0) {
            cholesky_checks++;
            if (!test_cov_positive_definite(&filter)) {
                cholesky_failures++;
#ifdef PROPID_FUZZ_DEBUG
                propid_fuzz_debug_dump(&before, &filter);
#endif
                if (PROPID_FUZZ_CHOLESKY_ABORT) {
                    fail("covariance not positive definite");
                }
            }
        }
    }
    return 0;
}
