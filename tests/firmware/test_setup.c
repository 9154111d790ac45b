/*
 * Prepared setup (propid_setup_prepare, propid_init_prepared): a filter started
 * from a prepared setup is the filter propid_init makes from the same config, to
 * the byte, before and after a flight; a setup of another format or size, with a
 * damaged byte, or forged with a matching checksum but indices the step cannot
 * use is refused with PROPID_ERR_CONFIG and leaves a running filter untouched.
 */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "propid/propid.h"
#include "unity.h"
#include "test_vehicle.h"

#define ROTORS 4u

/* static: keep the test's stack small on the MCU */
static propid_config_t config;
static propid_setup_t setup;
static propid_setup_t forged;
static propid_filter_t from_config;
static propid_filter_t from_setup;
static propid_filter_t before;

void setUp(void)
{
    test_vehicle_config(&config, ROTORS, 0.17f, 0.7853982f);
    config.gate_sigma = 4.0f;
    config.gyro_bias_std0 = 0.02f;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_setup_prepare(&config, &setup));
}

void tearDown(void) {}

/* CRC-32 as zlib defines it, computed here from its table form (the library's is
 * bitwise): the checksum the host generator writes with Python's zlib.crc32. */
static uint32_t zlib_crc32(const uint8_t *bytes, size_t count)
{
    static uint32_t table[256];
    for (uint32_t n = 0; n < 256u; ++n) {
        uint32_t c = n;
        for (int k = 0; k < 8; ++k) {
            c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
        }
        table[n] = c;
    }
    uint32_t crc = 0xFFFFFFFFu;
    for (size_t k = 0; k < count; ++k) {
        crc = table[(crc ^ bytes[k]) & 0xFFu] ^ (crc >> 8);
    }
    return crc ^ 0xFFFFFFFFu;
}

static void reseal(propid_setup_t *s)
{
    s->checksum = zlib_crc32((const uint8_t *)s, offsetof(propid_setup_t, checksum));
}

static void fly(propid_filter_t *filter, uint32_t steps)
{
    uint64_t t = 1000u;
    for (uint32_t k = 0; k < steps; ++k) {
        const float phase = (float)(k % 40u) * 0.05f;
        const float speeds[ROTORS] = {900.0f + 40.0f * phase, 910.0f - 30.0f * phase, 890.0f + 20.0f * phase,
                                      905.0f - 10.0f * phase};
        const float gyro[3] = {0.01f * phase, -0.02f + 0.01f * phase, 0.005f};
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(filter, t, speeds, ROTORS));
        TEST_ASSERT_TRUE(propid_push_gyro(filter, t + 1000u, gyro) >= 0);
        t += 2000u;
    }
}

static void test_checksum_is_zlib_crc32(void)
{
    const uint8_t check[9] = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
    TEST_ASSERT_EQUAL_HEX32(0xCBF43926u, zlib_crc32(check, sizeof(check)));
    TEST_ASSERT_EQUAL_HEX32(zlib_crc32((const uint8_t *)&setup, offsetof(propid_setup_t, checksum)),
                            setup.checksum);
    TEST_ASSERT_EQUAL_HEX32(PROPID_SETUP_FORMAT, setup.format);
    TEST_ASSERT_EQUAL_UINT32(sizeof(propid_setup_t), setup.size);
}

static void test_prepared_filter_is_the_configured_one(void)
{
    memset(&from_config, 0xA5, sizeof(from_config));
    memset(&from_setup, 0x5A, sizeof(from_setup));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&from_config, &config));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init_prepared(&from_setup, &setup));
    TEST_ASSERT_EQUAL_MEMORY(&from_config, &from_setup, sizeof(from_config));
    fly(&from_config, 300u);
    fly(&from_setup, 300u);
    TEST_ASSERT_EQUAL_MEMORY(&from_config, &from_setup, sizeof(from_config));
}

static void test_prepare_rejects_a_bad_config(void)
{
    forged = setup;
    config.gate_sigma = 0.5f; /* below 1 sigma: propid_config_check refuses it */
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_setup_prepare(&config, &setup));
    TEST_ASSERT_EQUAL_MEMORY(&forged, &setup, sizeof(setup));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_setup_prepare(NULL, &setup));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_setup_prepare(&config, NULL));
}

/* A refused setup leaves a running filter as it was, one rejection counted. */
static void assert_refused(const propid_setup_t *bad)
{
    before = from_setup;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_init_prepared(&from_setup, bad));
    TEST_ASSERT_EQUAL_UINT32(before.counters.rejected[PROPID_REJECT_SLOT(PROPID_ERR_CONFIG)] + 1u,
                             from_setup.counters.rejected[PROPID_REJECT_SLOT(PROPID_ERR_CONFIG)]);
    from_setup.counters.rejected[PROPID_REJECT_SLOT(PROPID_ERR_CONFIG)]--;
    TEST_ASSERT_EQUAL_MEMORY(&before, &from_setup, sizeof(before));
}

static void test_bad_setups_are_refused(void)
{
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init_prepared(&from_setup, &setup));
    fly(&from_setup, 50u);
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_init_prepared(NULL, &setup));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_init_prepared(&from_setup, NULL));

    forged = setup; /* another version or build */
    forged.format ^= 1u << 8;
    reseal(&forged);
    assert_refused(&forged);
    forged = setup;
    forged.size += 4u;
    reseal(&forged);
    assert_refused(&forged);
    /* One damaged byte anywhere before the checksum. */
    const size_t spots[4] = {offsetof(propid_setup_t, config), offsetof(propid_setup_t, derived),
                             offsetof(propid_setup_t, derived) + sizeof(setup.derived) / 2u,
                             offsetof(propid_setup_t, checksum) - 1u};
    for (size_t k = 0; k < 4u; ++k) {
        forged = setup;
        ((uint8_t *)&forged)[spots[k]] ^= 0x10u;
        assert_refused(&forged);
    }
    forged = setup;
    forged.checksum ^= 1u;
    assert_refused(&forged);
    /* Sealed, but indices the step would use out of the filter's bounds. */
    forged = setup;
    forged.derived.state_count = (uint8_t)(PROPID_MAX_STATES + 1u);
    reseal(&forged);
    assert_refused(&forged);
    forged = setup;
    forged.derived.layout.drag = 0u;
    reseal(&forged);
    assert_refused(&forged);
    forged = setup;
    forged.config.rotor_count = (uint8_t)(PROPID_MAX_ROTORS + 1u);
    reseal(&forged);
    assert_refused(&forged);
    /* The genuine one still starts it. */
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init_prepared(&from_setup, &setup));
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_checksum_is_zlib_crc32);
    RUN_TEST(test_prepared_filter_is_the_configured_one);
    RUN_TEST(test_prepare_rejects_a_bad_config);
    RUN_TEST(test_bad_setups_are_refused);
    return UNITY_END();
}
