/* Test helper shared by the Unity suites and the fuzz harness: does the filter's
 * covariance (its packed upper triangle) factor by Cholesky in double precision,
 * i.e. is P positive definite? Double so that the check's own rounding does not
 * decide a float32 covariance's verdict. */
#ifndef PROPID_TEST_COV_POSITIVE_DEFINITE_H
#define PROPID_TEST_COV_POSITIVE_DEFINITE_H

#include <math.h>
#include <stdint.h>

#include "propid/propid.h"

static inline int test_cov_positive_definite(const propid_filter_t *filter)
{
    /* static: a 30x30 double factor is too large for a Cortex-M4 test's stack */
    static double factor[PROPID_MAX_STATES][PROPID_MAX_STATES];
    const uint8_t n = filter->derived.state_count;
    for (uint8_t i = 0; i < n; ++i) {
        for (uint8_t j = 0; j <= i; ++j) {
            double sum = (double)filter->core.cov[propid_cov_index(j, i)]; /* upper triangle: (j, i), j <= i */
            for (uint8_t k = 0; k < j; ++k) {
                sum -= factor[i][k] * factor[j][k];
            }
            if (i == j) {
                if (!(sum > 0.0)) {
                    return 0;
                }
                factor[i][i] = sqrt(sum);
            } else {
                factor[i][j] = sum / factor[j][j];
            }
        }
    }
    return 1;
}

#endif
