/*
 * The NEES's truth (sitl_honesty_truth): with the thrust-torque scale state the
 * thrust states are g_i = s kf_i / kf_nominal_i and the scale state r = 1/s
 * (docs/math.md §9), so their truth is s_true kf_true_i / kf_nominal_i and
 * 1 / s_true; without it kf_true_i / kf_nominal_i. A filter sitting exactly on
 * that truth has a NEES of zero. s_true (sitl_setup_true_torque_scale) is the
 * file's inertia over the plant's true one.
 *
 * The NEES's per-rotor coefficient entries (sitl_honesty_coeff_per_rotor) against
 * the filter's own map of the whole state and covariance (propid_coeff_flip):
 * bit for bit on every entry the NEES reads, quad and hexa, and the columns it
 * does not read (the rates') left in the kept bases.
 *
 * The lost rotor's recovery (sitl_honesty_add / _finish): asked of a loss whose
 * rotor was within 10 % just before it (changed_rotor_from_inside), and counted
 * recovered when that rotor's kf and km came back within 10 % and stayed.
 */
#include <float.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "../../firmware/src/propid_internal.h"
#include "effects.h"
#include "honesty.h"
#include "plant.h"
#include "sim.h"
#include "unity.h"

void setUp(void)
{
}

void tearDown(void)
{
}

/* An initialised filter whose state and covariance hold distinct values in
 * every used entry (a symmetric matrix is not needed: the maps are linear). */
static void filter_with_pattern(propid_filter_t *filter, uint8_t rotors)
{
    propid_config_t config;
    propid_config_default(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(&config, rotors, 0.17f, 0.785398f,
                                                                 1.0f, 5.57e-6f, 1.36e-7f));
    propid_config_set_inertia_diag(&config, 3.65e-3f, 3.68e-3f, 7.03e-3f);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(filter, &config));
    const uint8_t states = filter->derived.state_count;
    for (uint8_t i = 0; i < states; ++i) {
        filter->core.state[i] = 1.0f + 0.37f * sinf(1.3f * (float)i);
        for (uint8_t j = i; j < states; ++j) {
            filter->core.cov[propid_cov_index(i, j)] = 0.01f * cosf(0.7f * (float)i + 1.9f * (float)j);
        }
    }
}

static void check_rotors(uint8_t rotors)
{
    static propid_filter_t filter;
    filter_with_pattern(&filter, rotors);
    const propid_layout_t *layout = &filter.derived.layout;
    uint8_t columns[PROPID_MAX_ROTORS + 3];
    int count = 0;
    for (uint8_t i = 0; i < rotors; ++i) {
        columns[count++] = (uint8_t)(layout->thrust + i);
    }
    for (uint8_t a = 0; a < 3; ++a) {
        columns[count++] = (uint8_t)(layout->gyro_bias + a);
    }
    propid_core_t whole = filter.core, part = filter.core;
    propid_coeff_flip(&filter.derived, &filter.config, &whole, 1);
    sitl_honesty_coeff_per_rotor(&filter, columns, count, &part);
    /* The thrust block: state, block and the columns the NEES reads as the whole flip's. */
    int thrust_changed = 0;
    for (uint8_t i = 0; i < rotors; ++i) {
        const uint8_t t = (uint8_t)(layout->thrust + i);
        TEST_ASSERT_EQUAL_UINT32(0, memcmp(&whole.state[t], &part.state[t], sizeof(float)));
        for (uint8_t j = 0; j < rotors; ++j) {
            const uint32_t k = propid_cov_index(t, (uint8_t)(layout->thrust + j));
            TEST_ASSERT_EQUAL_UINT32(0, memcmp(&whole.cov[k], &part.cov[k], sizeof(float)));
            thrust_changed += whole.cov[k] != filter.core.cov[k];
        }
        for (uint8_t a = 0; a < 3; ++a) {
            const uint32_t k = propid_cov_index(t, (uint8_t)(layout->gyro_bias + a));
            TEST_ASSERT_EQUAL_UINT32(0, memcmp(&whole.cov[k], &part.cov[k], sizeof(float)));
            thrust_changed += whole.cov[k] != filter.core.cov[k];
        }
        /* A rate column is not read: still in the torque basis. */
        const uint32_t k = propid_cov_index(t, 0);
        TEST_ASSERT_EQUAL_UINT32(0, memcmp(&filter.core.cov[k], &part.cov[k], sizeof(float)));
    }
    TEST_ASSERT_TRUE(thrust_changed > 0);

    const uint8_t first = (uint8_t)layout->drag;
    int changed = 0;
    for (uint8_t i = 0; i < rotors; ++i) {
        const uint8_t d = (uint8_t)(first + i);
        TEST_ASSERT_EQUAL_UINT32(0, memcmp(&whole.state[d], &part.state[d], sizeof(float)));
        changed += whole.state[d] != filter.core.state[d];
        for (uint8_t j = 0; j < rotors; ++j) {
            const uint32_t k = propid_cov_index(d, (uint8_t)(first + j));
            TEST_ASSERT_EQUAL_UINT32(0, memcmp(&whole.cov[k], &part.cov[k], sizeof(float)));
        }
        for (int c = 0; c < count; ++c) {
            const uint32_t k = propid_cov_index(d, columns[c]);
            TEST_ASSERT_EQUAL_UINT32(0, memcmp(&whole.cov[k], &part.cov[k], sizeof(float)));
            changed += whole.cov[k] != filter.core.cov[k];
        }
        /* A rate column was not asked for: still in the yaw basis. */
        const uint32_t k = propid_cov_index(d, 0);
        TEST_ASSERT_EQUAL_UINT32(0, memcmp(&filter.core.cov[k], &part.cov[k], sizeof(float)));
    }
    TEST_ASSERT_TRUE(changed > 0); /* the map did something, so the comparison can fail */
}

static void test_quad_matches_the_whole_flip(void)
{
    check_rotors(4);
}

static void test_hexa_matches_the_whole_flip(void)
{
    check_rotors(6);
}

/* A quad filter with the accelerometer; scale: the thrust-torque scale state. */
static void aided_filter(propid_filter_t *filter, int scale)
{
    propid_config_t config;
    propid_config_default(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(&config, 4, 0.17f, 0.785398f,
                                                                 1.0f, 5.57e-6f, 1.36e-7f));
    propid_config_set_inertia_diag(&config, 3.65e-3f, 3.68e-3f, 7.03e-3f);
    config.mass = 1.5f;
    config.torque_scale = (uint8_t)scale;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(filter, &config));
}

static const double true_kf[4] = {5.3e-6, 5.9e-6, 5.6e-6, 5.1e-6};
static const double true_km[4] = {1.30e-7, 1.41e-7, 1.36e-7, 1.33e-7};
static const double true_bias[3] = {0.01, -0.02, 0.005};
static const double nominal_kf = (double)5.57e-6f, nominal_km = (double)1.36e-7f; /* as configured */

static void test_truth_with_the_scale_state_is_s_kf_and_1_over_s(void)
{
    static propid_filter_t filter;
    aided_filter(&filter, 1);
    const double s_true = 1.0 / 1.3; /* the true inertia 1.3 x the file's */
    int index[SITL_HONESTY_MAX_DOF];
    double truth[SITL_HONESTY_MAX_DOF];
    const int n = sitl_honesty_truth(&filter, s_true, true_kf, true_km, true_bias, index, truth);
    const propid_layout_t *layout = &filter.derived.layout;
    TEST_ASSERT_EQUAL_INT(2 * 4 + 4, n);
    for (int i = 0; i < 4; i++) {
        TEST_ASSERT_EQUAL_INT(layout->thrust + i, index[i]);
        TEST_ASSERT_DOUBLE_WITHIN(1e-12, s_true * true_kf[i] / nominal_kf, truth[i]);
        TEST_ASSERT_EQUAL_INT(layout->drag + i, index[4 + i]);
        TEST_ASSERT_DOUBLE_WITHIN(1e-12, true_km[i] / nominal_km, truth[4 + i]);
    }
    TEST_ASSERT_EQUAL_INT(layout->torque_scale, index[n - 1]);
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, 1.3, truth[n - 1]);
}

static void test_truth_without_the_scale_state_is_kf(void)
{
    static propid_filter_t filter;
    aided_filter(&filter, 0);
    int index[SITL_HONESTY_MAX_DOF];
    double truth[SITL_HONESTY_MAX_DOF];
    /* s_true is ignored: the thrust states are the coefficients themselves. */
    const int n = sitl_honesty_truth(&filter, 1.0 / 1.3, true_kf, true_km, true_bias, index, truth);
    TEST_ASSERT_EQUAL_INT(2 * 4 + 3, n);
    for (int i = 0; i < 4; i++) {
        TEST_ASSERT_DOUBLE_WITHIN(1e-12, true_kf[i] / nominal_kf, truth[i]);
    }
    for (int a = 0; a < 3; a++) {
        TEST_ASSERT_EQUAL_INT(filter.derived.layout.gyro_bias + a, index[8 + a]);
        TEST_ASSERT_EQUAL_DOUBLE(true_bias[a], truth[8 + a]);
    }
}

/* A filter whose states hold the truth of the scaled model reads a NEES near zero; read
 * against kf_true (s_true taken as 1, what the NEES did before) the same filter is far out
 * of its interval. */
static void test_filter_on_the_scaled_truth_has_a_zero_nees(void)
{
    static propid_filter_t filter;
    aided_filter(&filter, 1);
    const double s_true = 1.0 / 1.3;
    const propid_layout_t *layout = &filter.derived.layout;
    for (int i = 0; i < 4; i++) { /* the scaled model's truth, written out here */
        filter.core.state[layout->thrust + i] = (float)(s_true * true_kf[i] / nominal_kf);
        filter.core.state[layout->drag + i] = (float)(true_km[i] / nominal_km);
    }
    for (int a = 0; a < 3; a++) {
        filter.core.state[layout->gyro_bias + a] = (float)true_bias[a];
    }
    filter.core.state[layout->torque_scale] = (float)(1.0 / s_true);
    /* A filter that has learnt: its prior's covariance shrunk (std / 30), so an error along the
     * scale direction, which the prior allows, is far outside. */
    for (uint32_t k = 0; k < PROPID_COV_SIZE; k++) {
        filter.core.cov[k] *= 1e-3f;
    }
    /* The filter keeps the coefficient blocks in their bases (propid_internal.h). */
    const propid_reflection_t basis = propid_drag_basis(&filter.derived, &filter.config);
    propid_reflection_apply(&basis, &filter.core.state[filter.derived.layout.drag]);
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, &filter.derived, &filter.config);
    propid_thrust_to_basis(&thrust, &filter.core.state[filter.derived.layout.thrust]);
    propid_estimate_t estimate;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &estimate));
    for (int i = 0; i < 4; i++) { /* the firmware reads those states as kf = r g kf_nominal = kf_true */
        TEST_ASSERT_DOUBLE_WITHIN(1e-5 * true_kf[i], true_kf[i], (double)estimate.thrust_coeff[i]);
    }
    TEST_ASSERT_DOUBLE_WITHIN(1e-5, s_true, (double)estimate.torque_scale);
    sitl_honesty_t scaled, unscaled;
    sitl_honesty_init(&scaled, &filter, true_kf, true_km, s_true);
    sitl_honesty_init(&unscaled, &filter, true_kf, true_km, 1.0);
    TEST_ASSERT_EQUAL_INT(2 * 4 + 4, scaled.nees_dof);
    sitl_honesty_add(&scaled, 0.0, &estimate, &filter, true_kf, true_km, true_bias);
    sitl_honesty_add(&unscaled, 0.0, &estimate, &filter, true_kf, true_km, true_bias);
    TEST_ASSERT_EQUAL_INT(1, scaled.nees_samples);
    TEST_ASSERT_EQUAL_INT(1, unscaled.nees_samples);
    TEST_ASSERT_TRUE(scaled.nees_sum < 1e-3);
    TEST_ASSERT_TRUE(unscaled.nees_sum > 30.0); /* beyond the 95 % interval of 12 dof */
}

/* The gyro sees J^-1 (r x z) kf: with the file's J in the filter, the true torques carry
 * J_file / J_true, on every axis, as the plant builds its inertia from the effect. */
static void test_true_torque_scale_is_the_file_over_the_true_inertia(void)
{
    static const char *const effects[] = {NULL, "inertia_error=0.3", "inertia_error=-0.2", "com_offset"};
    static sitl_vehicle_t vehicle;
    static sitl_plant_t plant;
    sitl_vehicle_preset("hummingbird-plus", &vehicle);
    for (size_t k = 0; k < sizeof(effects) / sizeof(effects[0]); k++) {
        sitl_effects_t fx;
        char err[512];
        sitl_effects_clear(&fx);
        if (effects[k] != NULL) {
            TEST_ASSERT_EQUAL_INT_MESSAGE(0, sitl_effects_parse(&fx, effects[k], err, 512), err);
        }
        TEST_ASSERT_EQUAL_INT_MESSAGE(0, sitl_plant_init(&plant, &vehicle, NULL, NULL, &fx, err, 512), err);
        const double s_true = sitl_setup_true_torque_scale(&fx);
        for (int a = 0; a < 3; a++) {
            TEST_ASSERT_DOUBLE_WITHIN(1e-12, vehicle.inertia[a][a] / plant.inertia[a][a], s_true);
        }
    }
    sitl_effects_t fx;
    sitl_effects_clear(&fx);
    TEST_ASSERT_EQUAL_INT(0, sitl_effects_parse(&fx, "inertia_error=0.3", NULL, 0));
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, 1.0 / 1.3, sitl_setup_true_torque_scale(&fx)); /* not 1 */
}

/* One step of a quad whose estimate is the truth times (1 + off) on rotor `rotor`'s kf and km. */
static void step_with(sitl_honesty_t *h, const propid_filter_t *filter, double t, const double *kf,
                      const double *km, int rotor, double off)
{
    propid_estimate_t est;
    memset(&est, 0, sizeof(est));
    est.rotor_count = 4u;
    for (int i = 0; i < 4; i++) {
        const double scale = i == rotor ? 1.0 + off : 1.0;
        est.thrust_coeff[i] = (float)(kf[i] * scale);
        est.drag_coeff[i] = (float)(km[i] * scale);
    }
    const double bias[3] = {0.0, 0.0, 0.0};
    sitl_honesty_add(h, t, &est, filter, kf, km, bias);
}

static void test_lost_rotor_recovery_is_asked_of_an_accurate_rotor(void)
{
    static propid_filter_t filter;
    filter_with_pattern(&filter, 4u);
    const double kf0[4] = {5.57e-6, 5.57e-6, 5.57e-6, 5.57e-6};
    const double km0[4] = {1.36e-7, 1.36e-7, 1.36e-7, 1.36e-7};
    double kf[4], km[4];
    /* pre: rotor 2's error before the loss; post: after it, against the lost truth. */
    const struct {
        double pre, post;
        int from_inside, recovered;
    } cases[] = {
        {0.0, 0.0, 1, 1},   /* accurate before, follows the loss: recovered */
        {0.0, -0.3, 1, 0},  /* accurate before, 30 % off after: not recovered */
        {0.2, 0.0, 0, 1},   /* 20 % off before: comes back, but was never asked */
        {0.2, 0.2, 0, 0},   /* 20 % off before and after */
    };
    for (size_t c = 0; c < sizeof(cases) / sizeof(cases[0]); c++) {
        memcpy(kf, kf0, sizeof(kf));
        memcpy(km, km0, sizeof(km));
        sitl_honesty_t h;
        sitl_honesty_init(&h, &filter, kf, km, 1.0);
        for (int k = 0; k < 20; k++) {
            step_with(&h, &filter, 0.002 * k, kf, km, 2, cases[c].pre);
        }
        kf[2] *= 0.7; /* the loss */
        km[2] *= 0.7;
        for (int k = 20; k < 40; k++) {
            /* the step of the loss itself still carries the old estimate */
            const double post = k == 20 ? (1.0 + cases[c].pre) / 0.7 - 1.0 : cases[c].post;
            step_with(&h, &filter, 0.002 * k, kf, km, 2, post);
        }
        sitl_honesty_finish(&h);
        TEST_ASSERT_EQUAL_INT(1, h.changes);
        TEST_ASSERT_EQUAL_INT(cases[c].recovered, h.rotor_recovered);
        TEST_ASSERT_EQUAL_INT(cases[c].from_inside, h.rotor_changes_from_inside);
        TEST_ASSERT_EQUAL_INT(cases[c].from_inside && cases[c].recovered, h.rotor_recovered_from_inside);
    }
}

/* A hummingbird-sized quad filter at its prior, on the nominal coefficients; its
 * first estimate and the truth it is scored against (its own coefficients, no bias). */
static void init_nominal_hummingbird_filter(propid_filter_t *filter, propid_estimate_t *estimate, double kf[4],
                                            double km[4], double bias[3])
{
    propid_config_t config;
    propid_config_default(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(&config, 4u, 0.17f, 0.785398f, 1.0f,
                                                                 (float)nominal_kf, (float)nominal_km));
    propid_config_set_inertia_diag(&config, 3.65e-3f, 3.68e-3f, 7.03e-3f);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(filter, &config));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(filter, estimate));
    for (int i = 0; i < 4; i++) {
        kf[i] = nominal_kf;
        km[i] = nominal_km;
    }
    bias[0] = bias[1] = bias[2] = 0.0;
}

/* The definiteness check reads the filter's whole P, not only the NEES block: the prior
 * passes; two body rates correlated beyond 1 (states the NEES does not read) fail it while
 * the NEES is still taken; a coefficient pair correlated beyond 1 fails both (the NEES
 * sample is skipped). */
static void test_covariance_check_reads_the_whole_p(void)
{
    static propid_filter_t filter;
    propid_estimate_t estimate;
    double kf[4], km[4], bias[3];
    init_nominal_hummingbird_filter(&filter, &estimate, kf, km, bias);
    sitl_honesty_t h;
    sitl_honesty_init(&h, &filter, kf, km, 1.0); /* off unless asked (--honesty-cov-check) */
    sitl_honesty_add(&h, 0.0, &estimate, &filter, kf, km, bias);
    TEST_ASSERT_EQUAL_INT(0, h.cov_checks);
    sitl_honesty_init(&h, &filter, kf, km, 1.0);
    h.check_cov = 1;
    sitl_honesty_add(&h, 0.0, &estimate, &filter, kf, km, bias);
    TEST_ASSERT_EQUAL_INT(1, h.cov_checks);
    TEST_ASSERT_EQUAL_INT(0, h.cov_not_pd);
    TEST_ASSERT_EQUAL_INT(1, h.nees_samples);

    const float rate_var = filter.core.cov[propid_cov_index(0u, 0u)];
    filter.core.cov[propid_cov_index(0u, 1u)] = 1.5f * rate_var; /* correlation 1.5 */
    sitl_honesty_init(&h, &filter, kf, km, 1.0);
    h.check_cov = 1;
    sitl_honesty_add(&h, 0.0, &estimate, &filter, kf, km, bias);
    TEST_ASSERT_EQUAL_INT(1, h.cov_not_pd);
    TEST_ASSERT_EQUAL_INT(1, h.nees_samples);

    filter.core.cov[propid_cov_index(0u, 1u)] = 0.0f;
    const uint8_t kf0 = filter.derived.layout.thrust;
    filter.core.cov[propid_cov_index(kf0, (uint8_t)(kf0 + 1u))] = 1.5f * filter.core.cov[propid_cov_index(kf0, kf0)];
    sitl_honesty_init(&h, &filter, kf, km, 1.0);
    h.check_cov = 1;
    sitl_honesty_add(&h, 0.0, &estimate, &filter, kf, km, bias);
    TEST_ASSERT_EQUAL_INT(1, h.cov_not_pd);
    TEST_ASSERT_EQUAL_INT(0, h.nees_samples);
}

/* Each NEES sample falls on one side of its 95 % interval or in it: a filter on the truth
 * (NEES 0) is below it, the same error direction scaled to a NEES of the dof is inside, and
 * scaled to 4 times that it is above (chi-square(11) interval about [3.8, 21.9]). */
static void test_nees_sample_counted_below_inside_or_above_its_interval(void)
{
    static propid_filter_t filter;
    propid_estimate_t estimate;
    double kf[4], km[4], bias[3];
    init_nominal_hummingbird_filter(&filter, &estimate, kf, km, bias);
    const double direction_kf[4] = {0.05, -0.03, 0.02, 0.04}; /* relative errors */
    const double direction_km[4] = {-0.02, 0.06, 0.01, -0.04};
    const double direction_bias[3] = {2e-3, -1e-3, 3e-3};     /* rad/s */
    double unit_nees = 0.0;
    const double scales[4] = {0.0, 1.0, -1.0, -1.0}; /* -1: set from unit_nees below */
    const long below[4] = {1, -1, 0, 0}, inside[4] = {0, -1, 1, 0}, above[4] = {0, -1, 0, 1};
    for (int c = 0; c < 4; c++) {
        double scale = scales[c];
        if (c == 2) {
            scale = sqrt(11.0 / unit_nees);
        } else if (c == 3) {
            scale = 2.0 * sqrt(11.0 / unit_nees); /* NEES 44 */
        }
        double true_kf[4], true_km[4], true_bias[3];
        for (int i = 0; i < 4; i++) {
            true_kf[i] = kf[i] * (1.0 + scale * direction_kf[i]);
            true_km[i] = km[i] * (1.0 + scale * direction_km[i]);
        }
        for (int a = 0; a < 3; a++) {
            true_bias[a] = bias[a] + scale * direction_bias[a];
        }
        sitl_honesty_t h;
        sitl_honesty_init(&h, &filter, true_kf, true_km, 1.0);
        TEST_ASSERT_EQUAL_INT(11, h.nees_dof);
        sitl_honesty_add(&h, 0.0, &estimate, &filter, true_kf, true_km, true_bias);
        TEST_ASSERT_EQUAL_INT(1, h.nees_samples);
        TEST_ASSERT_EQUAL_INT(1, h.nees_below_bounds + h.nees_in_bounds + h.nees_above_bounds);
        if (c == 1) {
            unit_nees = h.nees_sum;
            TEST_ASSERT_TRUE(unit_nees > 0.0);
            continue;
        }
        TEST_ASSERT_EQUAL_INT(below[c], h.nees_below_bounds);
        TEST_ASSERT_EQUAL_INT(inside[c], h.nees_in_bounds);
        TEST_ASSERT_EQUAL_INT(above[c], h.nees_above_bounds);
    }
}

/* A step counts as non-finite when any reported value or std is Inf or NaN, and not
 * when all are finite, however large (FLT_MAX in every field). */
static void test_nonfinite_estimate_is_counted(void)
{
    static propid_filter_t filter;
    propid_estimate_t estimate;
    double kf[4], km[4], bias[3];
    init_nominal_hummingbird_filter(&filter, &estimate, kf, km, bias);
    sitl_honesty_t h;
    sitl_honesty_init(&h, &filter, kf, km, 1.0);
    sitl_honesty_add(&h, 0.0, &estimate, &filter, kf, km, bias);
    TEST_ASSERT_EQUAL_INT(0, h.nonfinite_estimates);

    propid_estimate_t big = estimate;
    for (int i = 0; i < 4; i++) {
        big.thrust_coeff[i] = big.thrust_coeff_std[i] = big.drag_coeff[i] = big.drag_coeff_std[i] = FLT_MAX;
    }
    for (int a = 0; a < 3; a++) {
        big.gyro_bias[a] = big.gyro_bias_std[a] = big.body_rate[a] = big.body_rate_std[a] = FLT_MAX;
    }
    sitl_honesty_add(&h, 0.002, &big, &filter, kf, km, bias);
    TEST_ASSERT_EQUAL_INT(0, h.nonfinite_estimates);

    float *fields[] = {&estimate.thrust_coeff[3], &estimate.drag_coeff_std[0], &estimate.gyro_bias[2],
                       &estimate.body_rate_std[1]};
    const float bad[] = {INFINITY, -INFINITY, NAN};
    long expected = 0;
    for (size_t f = 0; f < sizeof(fields) / sizeof(fields[0]); f++) {
        for (size_t b = 0; b < sizeof(bad) / sizeof(bad[0]); b++) {
            const float kept = *fields[f];
            *fields[f] = bad[b];
            sitl_honesty_add(&h, 0.004, &estimate, &filter, kf, km, bias);
            *fields[f] = kept;
            TEST_ASSERT_EQUAL_INT(++expected, h.nonfinite_estimates);
        }
    }
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_covariance_check_reads_the_whole_p);
    RUN_TEST(test_nees_sample_counted_below_inside_or_above_its_interval);
    RUN_TEST(test_nonfinite_estimate_is_counted);
    RUN_TEST(test_true_torque_scale_is_the_file_over_the_true_inertia);
    RUN_TEST(test_truth_with_the_scale_state_is_s_kf_and_1_over_s);
    RUN_TEST(test_truth_without_the_scale_state_is_kf);
    RUN_TEST(test_filter_on_the_scaled_truth_has_a_zero_nees);
    RUN_TEST(test_quad_matches_the_whole_flip);
    RUN_TEST(test_hexa_matches_the_whole_flip);
    RUN_TEST(test_lost_rotor_recovery_is_asked_of_an_accurate_rotor);
    return UNITY_END();
}
