/*
 * Model-consistency monitor (propid_consistency.c): on a synthetic flight whose
 * physics is exactly the filter's model, PROPID_HEALTH_MODEL_MISMATCH stays
 * down and the coefficients converge; with an unmodelled torque (what rotor
 * drag or a CoM offset add) it goes up within about a second, and the filter
 * never reports a coefficient converged while it is more than 5 % off.
 * Flight: quad X, rigid body integrated at 4 kHz, excitation + rate hold with
 * the nominal mixer, gyro white noise + constant bias at 500 Hz, ESC at 500 Hz.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "per_rotor_view.h"
#include "propid/propid.h"
#include "unity.h"
#include "test_rng.h"

#define SIM_PI 3.14159265358979f

void setUp(void) {}
void tearDown(void) {}

static float uniform(rng_t *rng)
{
    return ((float)(rng_next(rng) >> 8) + 0.5f) * (1.0f / 16777216.0f);
}

static float normal(rng_t *rng)
{
    const float u1 = uniform(rng);
    const float u2 = uniform(rng);
    return sqrtf(-2.0f * logf(u1)) * cosf(2.0f * SIM_PI * u2);
}

#define ARM 0.17f
#define KF_NOMINAL 5.57e-6f
#define KM_NOMINAL 1.36e-7f
static const float inertia[3] = {3.65e-3f, 3.68e-3f, 7.03e-3f};

typedef struct {
    float duration_s;
    float unmodelled;       /* amplitude of the unmodelled angular acceleration [rad/s^2] */
    float spike_rate;       /* probability of a 1 rad/s gyro spike per sample */
    float rate_noise;       /* filter rate_process_noise */
    uint32_t seed;
    float inertia_error;    /* true inertia = the configured one x (1 + this) */
    float inertia_rel_std;  /* what the configuration says of its inertia (inertia_rel_std) */
} flight_t;

typedef struct {
    uint32_t reads;             /* coefficient reads (8 per estimate read) */
    uint32_t false_converged;   /* coefficient reads "converged" while > 5 % off */
    uint32_t false_after_flag;  /* the same, after the first MODEL_MISMATCH */
    uint32_t flagged_reads;     /* estimates read with MODEL_MISMATCH up */
    float first_flag_s;         /* time of the first MODEL_MISMATCH (< 0: never) */
    float final_rel_err_max;
    uint16_t final_converged;   /* thrust bits | drag bits << 8 at the end */
    int would_have_converged;   /* every variance below converged_rel_std^2 at the end */
    uint16_t std_claims;        /* bits (as final_converged) with 3 std < converged_rel_std */
} result_t;

static propid_filter_t filter;

static void configure(const flight_t *flight, propid_config_t *config)
{
    propid_config_default(config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(config, 4u, ARM, SIM_PI / 4.0f, 1.0f,
                                                                 KF_NOMINAL, KM_NOMINAL));
    propid_config_set_inertia_diag(config, inertia[0], inertia[1], inertia[2]);
    config->rate_process_noise = flight->rate_noise;
    config->thrust_coeff_rel_walk = 0.0f;
    config->drag_coeff_rel_walk = 0.0f;
    config->inertia_rel_std = flight->inertia_rel_std;
}

/* Control tick: the squared speeds reach next_sq now; the new target is the
 * excitation + rate hold allocated with the nominal mixer (X frame). */
static void control(const propid_config_t *config, float t, const float rate[3], float hover,
                    float now_sq[4], float next_sq[4])
{
    const float accel[3] = {
        20.0f * (sinf(2.0f * SIM_PI * 1.3f * t) + 0.5f * sinf(2.0f * SIM_PI * 3.7f * t)),
        20.0f * (sinf(2.0f * SIM_PI * 1.7f * t + 1.0f) + 0.5f * sinf(2.0f * SIM_PI * 4.3f * t)),
        10.0f * (sinf(2.0f * SIM_PI * 0.9f * t + 2.0f) + 0.5f * sinf(2.0f * SIM_PI * 2.9f * t))};
    float torque[3];
    for (int a = 0; a < 3; ++a) {
        torque[a] = inertia[a] * (accel[a] - 4.0f * rate[a]);
    }
    const float collective = hover * hover * (1.0f + 0.25f * sinf(2.0f * SIM_PI * 0.6f * t));
    for (int i = 0; i < 4; ++i) {
        const propid_rotor_config_t *rotor = &config->rotor[i];
        const float tx = rotor->position_m[1] * KF_NOMINAL;
        const float ty = -rotor->position_m[0] * KF_NOMINAL;
        const float tz = rotor->yaw_sign * KM_NOMINAL;
        /* X frame: T T^T is diagonal, row a's squared norm 4 t_a^2. */
        const float u = collective + torque[0] / (4.0f * tx) + torque[1] / (4.0f * ty) + torque[2] / (4.0f * tz);
        now_sq[i] = next_sq[i];
        next_sq[i] = u > 0.0f ? u : 0.0f;
    }
}

/* One read of the estimate, as an autopilot would: flag and false "converged". */
static void observe(float t, const float kf[4], const float km[4], result_t *out)
{
    propid_estimate_t est;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &est));
    if (est.health & PROPID_HEALTH_MODEL_MISMATCH) {
        out->flagged_reads++;
        if (out->first_flag_s < 0.0f) {
            out->first_flag_s = t;
        }
    }
    for (int i = 0; i < 4; ++i) {
        const int kf_false = ((est.thrust_coeff_converged >> i) & 1u) && fabsf(est.thrust_coeff[i] / kf[i] - 1.0f) > 0.05f;
        const int km_false = ((est.drag_coeff_converged >> i) & 1u) && fabsf(est.drag_coeff[i] / km[i] - 1.0f) > 0.05f;
        out->false_converged += (uint32_t)(kf_false + km_false);
        if (out->first_flag_s >= 0.0f) {
            out->false_after_flag += (uint32_t)(kf_false + km_false);
        }
    }
    out->reads += 8u;
}

static void fly(const flight_t *flight, result_t *out)
{
    propid_config_t config;
    configure(flight, &config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    rng_t rng = {flight->seed};
    float kf[4];
    float km[4];
    float bias[3];
    for (int i = 0; i < 4; ++i) {
        kf[i] = KF_NOMINAL * (1.0f + 0.4f * (uniform(&rng) - 0.5f));
        km[i] = KM_NOMINAL * (1.0f + 0.4f * (uniform(&rng) - 0.5f));
    }
    for (int a = 0; a < 3; ++a) {
        bias[a] = 0.02f * (uniform(&rng) - 0.5f);
    }
    const float gyro_std = config.gyro_noise_density * sqrtf(config.gyro_sample_rate_hz);
    const float hover = 0.6f * 1500.0f;
    float rate[3] = {0.0f, 0.0f, 0.0f};
    /* Squared speeds ramp linearly from one control tick's value to the next
     * (what the filter's trapezoid over the interval assumes): the command for
     * the next tick is decided at this one. */
    float now_sq[4];
    float next_sq[4];
    for (int i = 0; i < 4; ++i) {
        now_sq[i] = next_sq[i] = hover * hover;
    }
    float true_inertia[3];
    for (int a = 0; a < 3; ++a) {
        true_inertia[a] = inertia[a] * (1.0f + flight->inertia_error);
    }
    memset(out, 0, sizeof(*out));
    out->first_flag_s = -1.0f;
    const uint32_t end_us = (uint32_t)(flight->duration_s * 1.0e6f);
    const uint32_t tick_us = 2000u;
    const float h = 250.0e-6f;
    for (uint32_t t_us = 0u; t_us <= end_us; t_us += 250u) {
        const float t = (float)t_us * 1.0e-6f;
        if (t_us % tick_us == 0u) {
            control(&config, t, rate, hover, now_sq, next_sq);
            float speed[4];
            for (int i = 0; i < 4; ++i) {
                speed[i] = sqrtf(now_sq[i]);
            }
            TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, t_us, speed, 4u));
            if (t_us > 0u) {
                float gyro[3];
                for (int a = 0; a < 3; ++a) {
                    gyro[a] = rate[a] + bias[a] + gyro_std * normal(&rng);
                }
                if (uniform(&rng) < flight->spike_rate) {
                    gyro[0] += 1.0f;
                }
                TEST_ASSERT_TRUE(propid_push_gyro(&filter, t_us, gyro) >= 0);
                if (t_us % 10000u == 0u) {
                    observe(t, kf, km, out);
                }
            }
        }
        /* Truth: midpoint step; rotor torques with the true coefficients plus the
         * unmodelled torque (slowly varying, like rotor drag on a circle). */
        const float phase = (float)(t_us % tick_us) * 1.0e-6f / ((float)tick_us * 1.0e-6f);
        float mid[3];
        for (int pass = 0; pass < 2; ++pass) {
            const float *r = pass == 0 ? rate : mid;
            const float frac = pass == 0 ? phase : phase + 0.5f * h / ((float)tick_us * 1.0e-6f);
            const float tt = pass == 0 ? t : t + 0.5f * h;
            float torque[3] = {0.0f, 0.0f, 0.0f};
            for (int i = 0; i < 4; ++i) {
                const propid_rotor_config_t *rotor = &config.rotor[i];
                const float u = now_sq[i] + frac * (next_sq[i] - now_sq[i]);
                torque[0] += rotor->position_m[1] * kf[i] * u;
                torque[1] -= rotor->position_m[0] * kf[i] * u;
                torque[2] += rotor->yaw_sign * km[i] * u;
            }
            torque[0] += true_inertia[0] * flight->unmodelled * sinf(2.0f * SIM_PI * 0.3f * tt);
            torque[1] += true_inertia[1] * flight->unmodelled * cosf(2.0f * SIM_PI * 0.3f * tt);
            const float hx = true_inertia[0] * r[0];
            const float hy = true_inertia[1] * r[1];
            const float hz = true_inertia[2] * r[2];
            const float dot[3] = {(torque[0] - (r[1] * hz - r[2] * hy)) / true_inertia[0],
                                  (torque[1] - (r[2] * hx - r[0] * hz)) / true_inertia[1],
                                  (torque[2] - (r[0] * hy - r[1] * hx)) / true_inertia[2]};
            for (int a = 0; a < 3; ++a) {
                if (pass == 0) {
                    mid[a] = rate[a] + 0.5f * h * dot[a];
                } else {
                    rate[a] += h * dot[a];
                }
            }
        }
    }
    propid_estimate_t est;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &est));
    out->final_converged = (uint16_t)(est.thrust_coeff_converged | (est.drag_coeff_converged << 8));
    out->would_have_converged = 1;
    out->std_claims = 0u;
    const propid_core_t per_rotor = per_rotor_core(&filter);
    for (uint8_t i = 0; i < 4u; ++i) {
        const float third = config.converged_rel_std * config.converged_rel_std * (1.0f / 9.0f);
        out->std_claims |= (uint16_t)((per_rotor.cov[propid_cov_index(3u + i, 3u + i)] < third ? 1u : 0u) << i);
        out->std_claims |= (uint16_t)((per_rotor.cov[propid_cov_index(7u + i, 7u + i)] < third ? 1u : 0u) << (8u + i));
    }
    for (int i = 0; i < 4; ++i) {
        out->final_rel_err_max = fmaxf(out->final_rel_err_max, fabsf(est.thrust_coeff[i] / kf[i] - 1.0f));
        out->final_rel_err_max = fmaxf(out->final_rel_err_max, fabsf(est.drag_coeff[i] / km[i] - 1.0f));
    }
    for (uint8_t k = 3u; k < 11u; ++k) {
        if (!(per_rotor.cov[propid_cov_index(k, k)] < config.converged_rel_std * config.converged_rel_std)) {
            out->would_have_converged = 0;
        }
    }
#ifdef PROPID_TEST_VERBOSE
    propid_counters_t counters;
    (void)propid_get_counters(&filter, &counters);
    printf("reads %u after flag %u\n", (unsigned)out->reads, (unsigned)out->false_after_flag);
    printf("mismatch windows %u first %.2f s flagged reads %u false conv %u err %.3f conv 0x%x would %d\n",
           (unsigned)counters.model_mismatch, (double)out->first_flag_s, (unsigned)out->flagged_reads,
           (unsigned)out->false_converged, (double)out->final_rel_err_max, out->final_converged,
           out->would_have_converged);
#endif
}

/* Campaign-like tuning (tiny rate process noise: the model is trusted) and the
 * library default: on the model's own physics, no flag, and convergence.
 * "Converged" is 3 std < 5 % with the monitor vouching: every coefficient whose
 * std allows the claim makes it (the monitor withholds none on consistent
 * data), all eight with the campaign tuning; the library tuning's coefficient
 * walk keeps km's std at ~3.5 % after 20 s (no claim: its error may be 10 %). */
static void test_consistent_flight_is_not_flagged(void)
{
    const float noises[2] = {0.0004f, 0.2f};
    for (int k = 0; k < 2; ++k) {
        const flight_t flight = {20.0f, 0.0f, 0.0f, noises[k], 11u + (uint32_t)k, 0.0f, 0.0f};
        result_t out;
        fly(&flight, &out);
        propid_counters_t counters;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
        TEST_ASSERT_EQUAL_UINT32(0u, counters.model_mismatch);
        TEST_ASSERT_EQUAL_UINT32(0u, out.flagged_reads);
        TEST_ASSERT_EQUAL_UINT32(0u, out.false_converged);
        TEST_ASSERT_EQUAL_HEX16(out.std_claims, out.final_converged);
        TEST_ASSERT_EQUAL_HEX16(k == 0 ? 0x0F0F : 0x000F, out.final_converged);
        TEST_ASSERT_LESS_THAN_FLOAT(0.05f, out.final_rel_err_max);
    }
}

/* Gated gyro spikes are faults, not model errors: never flagged. They withhold
 * the claims of their window (the fault that sent them may have sent others
 * the gate let through): 1 % spikes gate some sample in every window, so no
 * claim, although the std alone would claim all eight and the error is small;
 * without spikes the same tuning claims all eight (the test above). */
static void test_gated_spikes_are_not_flagged_and_withhold_claims(void)
{
    const flight_t flight = {10.0f, 0.0f, 0.01f, 0.0004f, 21u, 0.0f, 0.0f};
    result_t out;
    fly(&flight, &out);
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
    TEST_ASSERT_TRUE(counters.axis_gated[0] > 20u);
    TEST_ASSERT_EQUAL_UINT32(0u, counters.model_mismatch);
    TEST_ASSERT_EQUAL_HEX16(0x0F0F, out.std_claims);
    TEST_ASSERT_LESS_THAN_FLOAT(0.05f, out.final_rel_err_max);
    TEST_ASSERT_EQUAL_HEX16(0u, out.final_converged);
}

/* An unmodelled torque: flagged early, and never "converged" while > 5 % off,
 * although the covariance alone would call every coefficient converged. */
static void test_unmodelled_torque_is_flagged(void)
{
    const flight_t flight = {20.0f, 8.0f, 0.0f, 0.0004f, 31u, 0.0f, 0.0f};
    result_t out;
    fly(&flight, &out);
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
    TEST_ASSERT_TRUE(counters.model_mismatch > 0u);
    TEST_ASSERT_TRUE(out.first_flag_s >= 0.0f && out.first_flag_s < 1.5f);
    TEST_ASSERT_EQUAL_UINT32(0u, out.false_after_flag);
    TEST_ASSERT_TRUE(out.false_converged * 100u < out.reads);
    /* The test can fail: the filter is wrong and its variances are small. */
    TEST_ASSERT_GREATER_THAN_FLOAT(0.05f, out.final_rel_err_max);
    TEST_ASSERT_TRUE(out.would_have_converged);
    TEST_ASSERT_EQUAL_HEX16(0u, out.final_converged);

    /* propid_reset: back to the prior, flag down, counter kept. */
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_reset(&filter));
    propid_estimate_t est;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &est));
    TEST_ASSERT_EQUAL_UINT32(0u, est.health & PROPID_HEALTH_MODEL_MISMATCH);
    propid_counters_t after;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &after));
    TEST_ASSERT_EQUAL_UINT32(counters.model_mismatch, after.model_mismatch);
}

/* The configured inertia 10 % below the true one (a CAD inertia): gyro and
 * rotor speeds see kf/J and km/J, so every coefficient settles ~9 % low with a
 * small std and nothing in the data is inconsistent. Told the inertia exact
 * (inertia_rel_std 0), the filter claims them converged: a claim about the
 * configured inertia's units only (the test can fail: the monitor stays
 * silent). Told how well the inertia is known (0.1), no claim is made. */
static void test_inertia_scale_error_is_counted_by_the_claim(void)
{
    const flight_t told_exact = {20.0f, 0.0f, 0.0f, 0.0004f, 41u, 0.1f, 0.0f};
    result_t out;
    fly(&told_exact, &out);
    TEST_ASSERT_EQUAL_UINT32(0u, out.flagged_reads);
    TEST_ASSERT_GREATER_THAN_FLOAT(0.05f, out.final_rel_err_max);
    TEST_ASSERT_TRUE(out.false_converged > 0u);
    TEST_ASSERT_EQUAL_HEX16(0x0F0F, out.final_converged);

    const flight_t told_cad = {20.0f, 0.0f, 0.0f, 0.0004f, 41u, 0.1f, 0.1f};
    fly(&told_cad, &out);
    TEST_ASSERT_GREATER_THAN_FLOAT(0.05f, out.final_rel_err_max);
    TEST_ASSERT_EQUAL_UINT32(0u, out.false_converged);
    TEST_ASSERT_EQUAL_HEX16(0u, out.final_converged);
    TEST_ASSERT_EQUAL_HEX16(0x0F0F, out.std_claims); /* the filter's own std alone would claim */

    /* A measured inertia (1 %) on exact physics: claims are still made. */
    const flight_t told_measured = {20.0f, 0.0f, 0.0f, 0.0004f, 11u, 0.0f, 0.01f};
    fly(&told_measured, &out);
    TEST_ASSERT_EQUAL_UINT32(0u, out.false_converged);
    TEST_ASSERT_EQUAL_HEX16(0x0F0F, out.final_converged);
    TEST_ASSERT_LESS_THAN_FLOAT(0.05f, out.final_rel_err_max);
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_consistent_flight_is_not_flagged);
    RUN_TEST(test_gated_spikes_are_not_flagged_and_withhold_claims);
    RUN_TEST(test_unmodelled_torque_is_flagged);
    RUN_TEST(test_inertia_scale_error_is_counted_by_the_claim);
    return UNITY_END();
}
