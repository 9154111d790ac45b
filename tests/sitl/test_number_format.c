/* sitl_format_g9 writes exactly what snprintf("%.9g") writes: over random
 * bit patterns, the values a flight log holds (floats widened, decimals,
 * powers of ten) and the neighbours of rounding ties. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "number_format.h"
#include "rng.h"
#include "unity.h"

void setUp(void) {}
void tearDown(void) {}

static long mismatches;
static char first_bad[128];

static void check(double x)
{
    char fast[SITL_G9_MAX], slow[64];
    int n = sitl_format_g9(x, fast);
    int m = snprintf(slow, sizeof(slow), "%.9g", x);
    if (n != m || strcmp(fast, slow) != 0) {
        if (mismatches++ == 0) {
            snprintf(first_bad, sizeof(first_bad), "%a: got '%s', printf '%s'", x, fast, slow);
        }
    }
}

static double from_bits(uint64_t bits)
{
    double x;
    memcpy(&x, &bits, sizeof(x));
    return x;
}

static void test_random_bit_patterns(void)
{
    sitl_rng_t rng;
    sitl_rng_init(&rng, 7, 1);
    for (int i = 0; i < 1000000; i++) {
        check(from_bits(sitl_rng_next(&rng)));
    }
    TEST_ASSERT_EQUAL_MESSAGE(0, mismatches, first_bad);
}

static void test_flight_log_like_values(void)
{
    sitl_rng_t rng;
    sitl_rng_init(&rng, 8, 2);
    for (int i = 0; i < 300000; i++) {
        /* magnitudes 1e-16 .. 1e24, both signs, and the same widened from float */
        double x = pow(10.0, -16.0 + 40.0 * sitl_rng_uniform(&rng));
        x = sitl_rng_uniform(&rng) < 0.5 ? -x : x;
        check(x);
        check((double)(float)x);
    }
    for (int k = -20; k <= 25; k++) { /* powers of ten and their neighbours */
        double p = pow(10.0, k);
        check(p);
        check(nextafter(p, 0.0));
        check(nextafter(p, INFINITY));
        check(-p);
    }
    for (int i = 0; i <= 20000; i++) { /* control-rate times and short decimals */
        check(0.002 * i);
        check((double)i * 1e-3);
        check(i / 7.0);
    }
    const double special[] = {0.0, -0.0, NAN, -NAN, INFINITY, -INFINITY, 1.0, 0.5, 1e-5, 1e-4,
                              99999999.95, 999999999.5, 123456789.0, 1234567890.0, 5e-324,
                              2.2250738585072014e-308, 1.7976931348623157e308};
    for (size_t i = 0; i < sizeof(special) / sizeof(special[0]); i++) {
        check(special[i]);
    }
    TEST_ASSERT_EQUAL_MESSAGE(0, mismatches, first_bad);
}

static void test_rounding_ties(void)
{
    /* d.dddddddd5 x 10^k: exactly half-way at nine digits in decimal, just
     * above or below in binary, plus the two neighbouring doubles. */
    sitl_rng_t rng;
    sitl_rng_init(&rng, 9, 3);
    for (int i = 0; i < 200000; i++) {
        double digits = (double)(100000000 + (int64_t)(sitl_rng_uniform(&rng) * 9e8));
        int k = -20 + (int)(sitl_rng_uniform(&rng) * 40.0);
        double x = (digits + 0.5) * pow(10.0, k - 8);
        check(x);
        check(nextafter(x, 0.0));
        check(nextafter(x, INFINITY));
    }
    for (int i = 1; i < 4096; i++) { /* exact binary ties: n + 1/2 and n / 2^k */
        check(100000000.5 + (double)i);
        check((double)i / 1024.0);
    }
    TEST_ASSERT_EQUAL_MESSAGE(0, mismatches, first_bad);
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_random_bit_patterns);
    RUN_TEST(test_flight_log_like_values);
    RUN_TEST(test_rounding_ties);
    return UNITY_END();
}
