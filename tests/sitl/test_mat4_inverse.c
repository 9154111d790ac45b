/*
 * sitl_mat4_inverse (cofactors) against Gauss-Jordan with pivoting
 * (sitl_mat4_solve) on matrices with unit-length rows, as the allocation
 * passes it; A inv = I; singular and near-singular input rejected with inv
 * untouched.
 */
#include <math.h>
#include <string.h>

#include "rng.h"
#include "sitl_math.h"
#include "unity.h"

void setUp(void)
{
}

void tearDown(void)
{
}

static void random_unit_rows(sitl_rng_t *rng, double a[4][4])
{
    for (int i = 0; i < 4; i++) {
        double norm = 0.0;
        for (int j = 0; j < 4; j++) {
            a[i][j] = sitl_rng_range(rng, -1.0, 1.0);
            norm += a[i][j] * a[i][j];
        }
        for (int j = 0; j < 4; j++) {
            a[i][j] /= sqrt(norm);
        }
    }
}

static void test_inverse_matches_gauss_jordan(void)
{
    sitl_rng_t rng;
    sitl_rng_init(&rng, 7, 0);
    int checked = 0;
    for (int trial = 0; trial < 2000; trial++) {
        double a[4][4], work[4][4], solved[4][4], inv[4][4];
        random_unit_rows(&rng, a);
        memcpy(work, a, sizeof(work));
        for (int i = 0; i < 4; i++) {
            for (int j = 0; j < 4; j++) {
                solved[i][j] = i == j ? 1.0 : 0.0;
            }
        }
        if (sitl_mat4_solve(work, solved, 4, 1e-3) != 0) {
            continue; /* badly conditioned draws: accuracy is not the point there */
        }
        TEST_ASSERT_EQUAL_INT(0, sitl_mat4_inverse(a, inv, 1e-9));
        for (int i = 0; i < 4; i++) {
            for (int j = 0; j < 4; j++) {
                double product = 0.0;
                for (int k = 0; k < 4; k++) {
                    product += a[i][k] * inv[k][j];
                }
                TEST_ASSERT_DOUBLE_WITHIN(1e-11, i == j ? 1.0 : 0.0, product);
                TEST_ASSERT_DOUBLE_WITHIN(1e-10 * (1.0 + fabs(solved[i][j])), solved[i][j], inv[i][j]);
            }
        }
        checked++;
    }
    TEST_ASSERT_TRUE(checked > 1000);
}

static void test_singular_rejected_and_inverse_untouched(void)
{
    double a[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 1, 0}}; /* rows 2 = 3 */
    double inv[4][4];
    for (int i = 0; i < 4; i++) {
        for (int j = 0; j < 4; j++) {
            inv[i][j] = 42.0;
        }
    }
    TEST_ASSERT_EQUAL_INT(-1, sitl_mat4_inverse(a, inv, 1e-9));
    a[3][3] = 1e-6; /* nearly: |det| = 1e-6 */
    TEST_ASSERT_EQUAL_INT(-1, sitl_mat4_inverse(a, inv, 1e-5));
    for (int i = 0; i < 4; i++) {
        for (int j = 0; j < 4; j++) {
            TEST_ASSERT_EQUAL_DOUBLE(42.0, inv[i][j]);
        }
    }
    TEST_ASSERT_EQUAL_INT(0, sitl_mat4_inverse(a, inv, 1e-7));
    TEST_ASSERT_DOUBLE_WITHIN(1e-3, 1e6, inv[3][3]);
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_inverse_matches_gauss_jordan);
    RUN_TEST(test_singular_rejected_and_inverse_untouched);
    return UNITY_END();
}
