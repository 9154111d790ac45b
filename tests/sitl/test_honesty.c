/*
 * The NEES's per-rotor drag entries (sitl_honesty_drag_per_rotor) against the
 * filter's own map of the whole state and covariance (propid_drag_basis_flip):
 * bit for bit on every entry the NEES reads, quad and hexa, and the columns it
 * is not asked for left in the yaw basis.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "../../firmware/src/propid_internal.h"
#include "honesty.h"
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
    const propid_drag_basis_t basis = propid_drag_basis(&filter.derived, &filter.config);
    propid_drag_basis_flip(&basis, &whole);
    sitl_honesty_drag_per_rotor(&filter, columns, count, &part);

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

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_quad_matches_the_whole_flip);
    RUN_TEST(test_hexa_matches_the_whole_flip);
    return UNITY_END();
}
