/*
 * Sensor models: gyro noise level and bias draw, saturation and quantisation;
 * ESC telemetry latency, DShot quantisation bound, dropout rate;
 * reproducibility of every random stream from the seed; sitl_rng_normals
 * against sitl_rng_normal called as often (the IMU draws its normals so), and the
 * IMU's normals drawn ahead against the model drawing them one by one.
 */
#include <math.h>
#include <string.h>

#include "esc_telemetry.h"
#include "imu.h"
#include "rng.h"
#include "unity.h"

void setUp(void)
{
}

void tearDown(void)
{
}

static void test_gyro_noise_matches_density_and_bias_in_range(void)
{
    sitl_imu_params_t p;
    sitl_imu_default_params(&p);
    p.gyro.bias_walk = 0.0;
    p.gyro.resolution = 0.0;
    sitl_effects_t fx;
    sitl_effects_clear(&fx);
    sitl_imu_t imu;
    sitl_imu_init(&imu, &p, 42, 42, &fx);
    for (int k = 0; k < 3; k++) {
        TEST_ASSERT_TRUE(fabs(imu.gyro_bias[k]) <= p.gyro.bias_max);
    }
    const int n = 20000;
    double sum[3] = {0}, sum2[3] = {0};
    double w[3] = {0.1, -0.2, 0.3}, f[3] = {0, 0, 9.81}, g[3], a[3];
    for (int i = 0; i < n; i++) {
        sitl_imu_sample(&imu, w, f, 1.0 / p.rate_hz, g, a);
        for (int k = 0; k < 3; k++) {
            double e = g[k] - w[k] - imu.gyro_bias[k];
            sum[k] += e;
            sum2[k] += e * e;
        }
    }
    double sigma = p.gyro.noise_density * sqrt(p.rate_hz);
    for (int k = 0; k < 3; k++) {
        double mean = sum[k] / n;
        double sd = sqrt(sum2[k] / n - mean * mean);
        TEST_ASSERT_DOUBLE_WITHIN(0.03 * sigma, sigma, sd);
        TEST_ASSERT_DOUBLE_WITHIN(4.0 * sigma / sqrt(n), 0.0, mean);
    }
}

static void test_gyro_saturates_and_quantises(void)
{
    sitl_imu_params_t p;
    sitl_imu_default_params(&p);
    p.gyro.noise_density = 0.0;
    p.gyro.bias_max = 0.0;
    p.gyro.bias_walk = 0.0;
    sitl_effects_t fx;
    sitl_effects_clear(&fx);
    sitl_imu_t imu;
    sitl_imu_init(&imu, &p, 1, 1, &fx);
    double w[3] = {100.0, -100.0, 0.01234}, f[3] = {0, 0, 9.81}, g[3], a[3];
    sitl_imu_sample(&imu, w, f, 0.001, g, a);
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, p.gyro.range, g[0]);
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, -p.gyro.range, g[1]);
    double lsb_count = g[2] / p.gyro.resolution;
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, round(lsb_count), lsb_count);
    TEST_ASSERT_DOUBLE_WITHIN(0.5 * p.gyro.resolution, 0.01234, g[2]);
}

static void test_esc_latency_and_dshot_quantisation(void)
{
    sitl_esc_params_t p;
    sitl_esc_default_params(&p);
    p.dropout_prob = 0.0;
    sitl_esc_telemetry_t esc;
    TEST_ASSERT_EQUAL_INT(0, sitl_esc_init(&esc, &p, 2, 0.0, 4000.0, 3));
    for (int k = 0; k <= 400; k++) {
        double t = k * 0.00025;
        double s[2] = {1500.0 + 2000.0 * t, 800.0};
        sitl_esc_record(&esc, t, s);
    }
    double out[2];
    TEST_ASSERT_EQUAL_INT(1, sitl_esc_report(&esc, 0.1, out));
    double truth = 1500.0 + 2000.0 * (0.1 - p.latency_s);
    /* e-period: 9-bit mantissa of whole microseconds -> relative error < 2 / 256. */
    TEST_ASSERT_DOUBLE_WITHIN(truth * 2.0 / 256.0, truth, out[0]);
    TEST_ASSERT_TRUE(out[0] != truth);
    /* Quantised values are exact decodes of a period. */
    double q = sitl_esc_quantise_dshot(1770.0, 7, 0);
    double period = 2.0 * 3.14159265358979323846 * 1e6 / (q * 7.0);
    TEST_ASSERT_DOUBLE_WITHIN(1e-6, round(period), period);
    TEST_ASSERT_DOUBLE_WITHIN(1770.0 * 0.003, 1770.0, q);
    TEST_ASSERT_EQUAL_DOUBLE(0.0, sitl_esc_quantise_dshot(0.0, 7, 0));
    TEST_ASSERT_EQUAL_DOUBLE(0.0, sitl_esc_quantise_dshot(0.5, 7, 0)); /* below the slowest period */
    sitl_esc_free(&esc);
}

/* The ESC truncates the period: decoded at the code's period a speed is too high by
 * half a step on average; decoded at the middle of the code's period interval the
 * error has mean 0 (over speeds spread across many codes, with and without the
 * mantissa shift) and each decode lies within the code's speed interval. */
static void test_esc_middle_decode_is_unbiased(void)
{
    const double bands[2][2] = {{1600.0, 1700.0}, {400.0, 500.0}}; /* periods < 511 us; 4 us codes */
    for (int b = 0; b < 2; b++) {
        double edge_sum = 0.0, middle_sum = 0.0, step_sum = 0.0;
        const int n = 20000;
        for (int k = 0; k < n; k++) {
            double speed = bands[b][0] + (bands[b][1] - bands[b][0]) * ((double)k + 0.5) / (double)n;
            double edge = sitl_esc_quantise_dshot(speed, 7, 0);
            double middle = sitl_esc_quantise_dshot(speed, 7, 1);
            double step = sitl_esc_dshot_step(speed, 7);
            TEST_ASSERT_TRUE(step > 0.0);
            TEST_ASSERT_TRUE(edge >= speed && edge - step < speed);
            TEST_ASSERT_TRUE(middle < edge && middle > edge - step);
            edge_sum += edge - speed;
            middle_sum += middle - speed;
            step_sum += step;
        }
        double mean_step = step_sum / n;
        TEST_ASSERT_DOUBLE_WITHIN(0.02 * mean_step, 0.5 * mean_step, edge_sum / n);
        TEST_ASSERT_DOUBLE_WITHIN(0.02 * mean_step, 0.0, middle_sum / n);
    }
    TEST_ASSERT_EQUAL_DOUBLE(0.0, sitl_esc_quantise_dshot(0.5, 7, 1));
}

static void test_esc_dropout_rate(void)
{
    sitl_esc_params_t p;
    sitl_esc_default_params(&p);
    p.dropout_prob = 0.2;
    sitl_esc_telemetry_t esc;
    TEST_ASSERT_EQUAL_INT(0, sitl_esc_init(&esc, &p, 1, 0.0, 1000.0, 9));
    double s = 1000.0, out;
    sitl_esc_record(&esc, 0.0, &s);
    int got = 0;
    const int n = 10000;
    for (int i = 0; i < n; i++) {
        got += sitl_esc_report(&esc, 0.0, &out);
    }
    TEST_ASSERT_DOUBLE_WITHIN(0.02, 0.8, (double)got / n);
    sitl_esc_free(&esc);
}

static void test_streams_are_reproducible_and_independent(void)
{
    sitl_rng_t a, b, c;
    sitl_rng_init(&a, 7, SITL_RNG_GYRO);
    sitl_rng_init(&b, 7, SITL_RNG_GYRO);
    sitl_rng_init(&c, 7, SITL_RNG_ESC);
    int same_ac = 0;
    for (int i = 0; i < 1000; i++) {
        double x = sitl_rng_normal(&a), y = sitl_rng_normal(&b), z = sitl_rng_normal(&c);
        TEST_ASSERT_EQUAL_DOUBLE(x, y);
        same_ac += x == z;
    }
    TEST_ASSERT_TRUE(same_ac < 5);
    sitl_rng_init(&a, 8, SITL_RNG_GYRO);
    sitl_rng_init(&b, 7, SITL_RNG_GYRO);
    TEST_ASSERT_TRUE(sitl_rng_next(&a) != sitl_rng_next(&b));
    /* Uniform range sanity. */
    for (int i = 0; i < 1000; i++) {
        double u = sitl_rng_range(&a, -2.0, 3.0);
        TEST_ASSERT_TRUE(u >= -2.0 && u < 3.0);
    }
}

/* Runs of 1 to 11 normals, a spare left over or not, through sitl_rng_normals and
 * through as many sitl_rng_normal calls: the same bits and the same stream after. */
static void test_normals_at_once_match_one_by_one(void)
{
    sitl_rng_t a, b;
    sitl_rng_init(&a, 11, SITL_RNG_GYRO);
    sitl_rng_init(&b, 11, SITL_RNG_GYRO);
    int mismatches = 0;
    for (int round = 0; round < 2000; round++) {
        const int count = 1 + round % 11;
        double batch[11];
        sitl_rng_normals(&a, batch, count);
        for (int i = 0; i < count; i++) {
            const double one = sitl_rng_normal(&b);
            mismatches += memcmp(&one, &batch[i], sizeof(one)) != 0;
        }
        mismatches += a.has_spare != b.has_spare || memcmp(a.s, b.s, sizeof(a.s)) != 0 ||
                       (a.has_spare && a.spare != b.spare);
    }
    TEST_ASSERT_EQUAL_INT(0, mismatches);
}

/* The IMU takes its normals from per-stream buffers drawn ahead: its samples are those
 * of the model with each normal drawn one by one at the sample (per axis: noise, then
 * walk; the accelerometer's stream only when it is read), bit for bit, across refills. */
static void test_imu_draws_ahead_match_one_by_one(void)
{
    sitl_imu_params_t p;
    sitl_imu_default_params(&p);
    p.gyro.range = p.gyro.resolution = 0.0;
    p.accel.range = p.accel.resolution = 0.0;
    sitl_effects_t fx;
    sitl_effects_clear(&fx);
    sitl_imu_t imu;
    sitl_imu_init(&imu, &p, 3, 5, &fx);
    double gyro_bias[3], accel_bias[3];
    memcpy(gyro_bias, imu.gyro_bias, sizeof(gyro_bias));
    memcpy(accel_bias, imu.accel_bias, sizeof(accel_bias));
    sitl_rng_t gyro_rng, accel_rng;
    sitl_rng_init(&gyro_rng, 5, SITL_RNG_GYRO);
    sitl_rng_init(&accel_rng, 5, SITL_RNG_ACCEL);
    const double dt = 1.0 / p.rate_hz, walk_g = p.gyro.bias_walk * sqrt(dt);
    const double walk_a = p.accel.bias_walk * sqrt(dt);
    int mismatches = 0;
    for (int k = 0; k < 41; k++) {
        const double w[3] = {0.1 * k, -0.2, 0.3}, f[3] = {0.5, -0.01 * k, 9.8};
        const int with_accel = k % 3 != 1;
        double g[3], a[3];
        sitl_imu_sample(&imu, w, f, dt, g, with_accel ? a : NULL);
        for (int i = 0; i < 3; i++) {
            const double ng = sitl_rng_normal(&gyro_rng), wg = sitl_rng_normal(&gyro_rng);
            gyro_bias[i] += walk_g * wg;
            const double want = w[i] + gyro_bias[i] + imu.gyro_sigma * ng;
            mismatches += memcmp(&want, &g[i], sizeof(want)) != 0;
            if (with_accel) {
                const double na = sitl_rng_normal(&accel_rng), wa = sitl_rng_normal(&accel_rng);
                accel_bias[i] += walk_a * wa;
                const double want_a = f[i] + accel_bias[i] + imu.accel_sigma * na;
                mismatches += memcmp(&want_a, &a[i], sizeof(want_a)) != 0;
            }
        }
    }
    TEST_ASSERT_EQUAL_INT(0, mismatches);
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_gyro_noise_matches_density_and_bias_in_range);
    RUN_TEST(test_gyro_saturates_and_quantises);
    RUN_TEST(test_esc_latency_and_dshot_quantisation);
    RUN_TEST(test_esc_middle_decode_is_unbiased);
    RUN_TEST(test_esc_dropout_rate);
    RUN_TEST(test_streams_are_reproducible_and_independent);
    RUN_TEST(test_normals_at_once_match_one_by_one);
    RUN_TEST(test_imu_draws_ahead_match_one_by_one);
    return UNITY_END();
}
