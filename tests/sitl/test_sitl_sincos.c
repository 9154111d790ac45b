/*
 * sitl_sincos against libm's sin and cos: within 2 units in the last place of
 * the libm value (and 2.5e-16 absolute) over the angles the simulator uses and
 * beyond (quadrant boundaries, large arguments up to the reduction limit);
 * libm's own values outside that range and for non-finite input. sitl_sincos4
 * against four sitl_sincos calls: the same bits in every lane.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "rng.h"
#include "sitl_sincos.h"
#include "unity.h"

void setUp(void)
{
}

void tearDown(void)
{
}

/* Error of got against want in units of the last place of want. */
static double ulps(double got, double want)
{
    const double ulp = nextafter(fabs(want), INFINITY) - fabs(want);
    return fabs(got - want) / ulp;
}

static void check_angle(double x, double *worst_ulps, double *worst_abs)
{
    double s, c;
    sitl_sincos(x, &s, &c);
    const double ws = sin(x), wc = cos(x);
    const double e = fmax(ulps(s, ws), ulps(c, wc));
    const double a = fmax(fabs(s - ws), fabs(c - wc));
    *worst_ulps = fmax(*worst_ulps, e);
    *worst_abs = fmax(*worst_abs, a);
}

static void test_agrees_with_libm_within_two_ulps(void)
{
    double worst_ulps = 0.0, worst_abs = 0.0;
    sitl_rng_t rng;
    sitl_rng_init(&rng, 12345u, 0u);
    /* The Box-Muller angle range, the trajectory's (omega t up to ~1e3 rad in
     * long flights), and up to the reduction limit. */
    const double ranges[] = {1e-6, 0.8, 2.0 * 3.14159265358979323846, 100.0, 1e4, 5e5};
    for (size_t r = 0; r < sizeof(ranges) / sizeof(ranges[0]); r++) {
        for (int i = 0; i < 100000; i++) {
            check_angle(sitl_rng_range(&rng, -ranges[r], ranges[r]), &worst_ulps, &worst_abs);
        }
    }
    /* Near every quadrant boundary k pi/4 up to k = 4000: the reduction picks
     * either neighbour there. */
    for (int k = -4000; k <= 4000; k++) {
        const double b = (double)k * (3.14159265358979323846 / 4.0);
        check_angle(b, &worst_ulps, &worst_abs);
        check_angle(nextafter(b, INFINITY), &worst_ulps, &worst_abs);
        check_angle(nextafter(b, -INFINITY), &worst_ulps, &worst_abs);
    }
    TEST_ASSERT_TRUE_MESSAGE(worst_ulps <= 2.0, "more than 2 ulps from libm");
    TEST_ASSERT_TRUE_MESSAGE(worst_abs <= 2.5e-16, "more than 2.5e-16 from libm");
}

static void test_exact_at_zero_and_libm_outside_the_range(void)
{
    double s, c;
    sitl_sincos(0.0, &s, &c);
    TEST_ASSERT_EQUAL_DOUBLE(0.0, s);
    TEST_ASSERT_EQUAL_DOUBLE(1.0, c);
    const double big[] = {6e5, -1e7, 1e300};
    for (int i = 0; i < 3; i++) {
        sitl_sincos(big[i], &s, &c);
        TEST_ASSERT_TRUE(s == sin(big[i]) && c == cos(big[i]));
    }
    sitl_sincos(NAN, &s, &c);
    TEST_ASSERT_TRUE(isnan(s) && isnan(c));
    sitl_sincos(INFINITY, &s, &c);
    TEST_ASSERT_TRUE(isnan(s) && isnan(c));
}

/* 1 when a and b have the same bits (tells -0 from +0). */
static int same_bits(double a, double b)
{
    return memcmp(&a, &b, sizeof(a)) == 0;
}

/* Four angles through sitl_sincos4 against four sitl_sincos calls. */
static int four_match(const double x[4])
{
    double s4[4], c4[4];
    sitl_sincos4(x, s4, c4);
    for (int i = 0; i < 4; i++) {
        double s, c;
        sitl_sincos(x[i], &s, &c);
        if (!(same_bits(s, s4[i]) || (isnan(s) && isnan(s4[i]))) ||
            !(same_bits(c, c4[i]) || (isnan(c) && isnan(c4[i])))) {
            return 0;
        }
    }
    return 1;
}

static void test_four_at_once_same_bits(void)
{
    sitl_rng_t rng;
    sitl_rng_init(&rng, 777u, 0u);
    const double ranges[] = {1e-6, 0.8, 2.0 * 3.14159265358979323846, 100.0, 1e4, 5e5};
    int mismatches = 0;
    for (size_t r = 0; r < sizeof(ranges) / sizeof(ranges[0]); r++) {
        for (int i = 0; i < 50000; i++) {
            double x[4];
            for (int j = 0; j < 4; j++) {
                x[j] = sitl_rng_range(&rng, -ranges[r], ranges[r]);
            }
            mismatches += !four_match(x);
        }
    }
    /* Every quadrant and its boundaries k pi/4 in every lane, and signed zeros. */
    for (int k = -4000; k <= 4000; k++) {
        const double b = (double)k * (3.14159265358979323846 / 4.0);
        const double x[4] = {b, nextafter(b, INFINITY), nextafter(b, -INFINITY), -b};
        mismatches += !four_match(x);
    }
    const double zeros[4] = {0.0, -0.0, 1e-300, -1e-300};
    mismatches += !four_match(zeros);
    /* One lane outside the reduction's range or not finite: libm's values there. */
    const double mixed[][4] = {{0.5, 6e5, -1.0, 2.0}, {NAN, 1.0, 2.0, 3.0}, {1.0, 2.0, 3.0, -INFINITY}};
    for (int m = 0; m < 3; m++) {
        mismatches += !four_match(mixed[m]);
    }
    TEST_ASSERT_EQUAL_INT(0, mismatches);
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_agrees_with_libm_within_two_ulps);
    RUN_TEST(test_exact_at_zero_and_libm_outside_the_range);
    RUN_TEST(test_four_at_once_same_bits);
    return UNITY_END();
}
