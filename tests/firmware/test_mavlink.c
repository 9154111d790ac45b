/*
 * MAVLink report packer: pack -> parse round trips through the generated
 * library's own byte parser (mavlink_parse_char), checksum, FLU->FRD signs,
 * sequence numbers, buffer-too-small rejection without writes, and the reset
 * command's decisions. Portable: runs on the host and under qemu-system-arm.
 */
#include <math.h>
#include <string.h>

#include "unity.h"

#include "propid/propid.h"
#include "propid/propid_mavlink.h"
#include "per_rotor_view.h"

#define MAVLINK_NO_CONVERSION_HELPERS
#include "mavlink_frames.h"

#define GUARD_LEN 32u

static propid_estimate_t estimate;
static propid_counters_t counters;
static propid_mavlink_sender_t sender;

static uint32_t float_bits(float value)
{
    uint32_t bits;
    memcpy(&bits, &value, sizeof bits);
    return bits;
}

#define ASSERT_SAME_FLOAT(expected, actual) \
    TEST_ASSERT_EQUAL_HEX32(float_bits(expected), float_bits(actual))

static void fill_estimate(uint8_t rotor_count)
{
    memset(&estimate, 0, sizeof estimate);
    estimate.time_us = 12345678901ull;
    estimate.rotor_count = rotor_count;
    for (uint8_t i = 0u; i < rotor_count; ++i) {
        const float k = (float)(i + 1u);
        estimate.thrust_coeff[i] = 2.3e-8f * (1.0f + 0.01f * k);
        estimate.thrust_coeff_std[i] = 1.0e-10f * k;
        estimate.drag_coeff[i] = 7.8e-10f * (1.0f - 0.02f * k);
        estimate.drag_coeff_std[i] = 3.0e-12f * k;
    }
    for (uint8_t axis = 0u; axis < 3u; ++axis) {
        const float a = (float)(axis + 1u);
        estimate.body_rate[axis] = 0.5f * a;
        estimate.body_rate_std[axis] = 0.01f * a;
        estimate.gyro_bias[axis] = 0.002f * a;
        estimate.gyro_bias_std[axis] = 0.0005f * a;
        estimate.innovation[axis] = -0.03f * a;
        estimate.innovation_test_ratio[axis] = 0.1f * a;
    }
    estimate.thrust_coeff_converging = 0x0Fu;
    estimate.thrust_coeff_converged = 0x05u;
    estimate.drag_coeff_converging = 0x0Au;
    estimate.drag_coeff_converged = 0x02u;
    estimate.health = PROPID_HEALTH_GATED | PROPID_HEALTH_COV_REPAIRED;
}

static void fill_counters(void)
{
    memset(&counters, 0, sizeof counters);
    counters.gyro_accepted = 500000u;
    counters.rotor_accepted = 250000u;
    counters.axis_gated[0] = 3u;
    counters.axis_gated[1] = 4u;
    counters.axis_gated[2] = 5u;
    counters.gate_reopened = 1u;
    counters.cov_repairs = 2u;
    counters.state_clamps = 6u;
    counters.resyncs = 7u;
    for (uint8_t reason = 1u; reason < PROPID_REJECT_SLOTS; ++reason) {
        counters.rejected[reason] = 10u * reason;
    }
}

void setUp(void)
{
    fill_estimate(4u);
    fill_counters();
    sender.system_id = 7u;
    sender.component_id = 42u;
    sender.sequence = 200u;
    mavlink_frames_reset();
}

void tearDown(void) {}

static void test_coefficients_round_trip(void)
{
    uint8_t buf[PROPID_MAVLINK_COEFFICIENTS_MAX_LEN + GUARD_LEN];
    uint16_t len = 0u;
    memset(buf, MAVLINK_FRAMES_GUARD_BYTE, sizeof buf);

    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_coefficients(&sender, &estimate, buf,
                                                           PROPID_MAVLINK_COEFFICIENTS_MAX_LEN,
                                                           &len));
    TEST_ASSERT_TRUE(len > 12u && len <= PROPID_MAVLINK_COEFFICIENTS_MAX_LEN);
    TEST_ASSERT_EQUAL_HEX8(MAVLINK_STX, buf[0]);
    TEST_ASSERT_EQUAL_UINT8(201u, sender.sequence);
    mavlink_frames_assert_untouched(&buf[PROPID_MAVLINK_COEFFICIENTS_MAX_LEN], GUARD_LEN);

    mavlink_message_t msg;
    TEST_ASSERT_EQUAL_UINT16(1u, mavlink_frames_parse(buf, len, &msg, 1u));
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_COEFFICIENTS, msg.msgid);
    TEST_ASSERT_EQUAL_UINT8(7u, msg.sysid);
    TEST_ASSERT_EQUAL_UINT8(42u, msg.compid);
    TEST_ASSERT_EQUAL_UINT8(200u, msg.seq);

    mavlink_propid_coefficients_t decoded;
    mavlink_msg_propid_coefficients_decode(&msg, &decoded);
    TEST_ASSERT_TRUE(decoded.time_usec == estimate.time_us);
    TEST_ASSERT_EQUAL_UINT8(4u, decoded.rotor_count);
    for (uint8_t i = 0u; i < 8u; ++i) {
        const int valid = i < 4u;
        ASSERT_SAME_FLOAT(valid ? estimate.thrust_coeff[i] : 0.0f, decoded.thrust_coeff[i]);
        ASSERT_SAME_FLOAT(valid ? estimate.thrust_coeff_std[i] : 0.0f, decoded.thrust_coeff_std[i]);
        ASSERT_SAME_FLOAT(valid ? estimate.drag_coeff[i] : 0.0f, decoded.drag_coeff[i]);
        ASSERT_SAME_FLOAT(valid ? estimate.drag_coeff_std[i] : 0.0f, decoded.drag_coeff_std[i]);
    }
    TEST_ASSERT_EQUAL_HEX16(0x0Fu, decoded.thrust_coeff_converging);
    TEST_ASSERT_EQUAL_HEX16(0x05u, decoded.thrust_coeff_converged);
    TEST_ASSERT_EQUAL_HEX16(0x0Au, decoded.drag_coeff_converging);
    TEST_ASSERT_EQUAL_HEX16(0x02u, decoded.drag_coeff_converged);
}

static void test_eight_rotors_round_trip(void)
{
    fill_estimate(8u);
    uint8_t buf[PROPID_MAVLINK_COEFFICIENTS_MAX_LEN];
    uint16_t len = 0u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_coefficients(&sender, &estimate, buf, sizeof buf, &len));
    mavlink_message_t msg;
    TEST_ASSERT_EQUAL_UINT16(1u, mavlink_frames_parse(buf, len, &msg, 1u));
    mavlink_propid_coefficients_t decoded;
    mavlink_msg_propid_coefficients_decode(&msg, &decoded);
    TEST_ASSERT_EQUAL_UINT8(8u, decoded.rotor_count);
    ASSERT_SAME_FLOAT(estimate.thrust_coeff[7], decoded.thrust_coeff[7]);
    ASSERT_SAME_FLOAT(estimate.drag_coeff_std[7], decoded.drag_coeff_std[7]);
}

static void test_gyro_round_trip_is_frd(void)
{
    uint8_t buf[PROPID_MAVLINK_GYRO_MAX_LEN];
    uint16_t len = 0u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_gyro(&sender, &estimate, buf, sizeof buf, &len));
    mavlink_message_t msg;
    TEST_ASSERT_EQUAL_UINT16(1u, mavlink_frames_parse(buf, len, &msg, 1u));
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_GYRO, msg.msgid);

    mavlink_propid_gyro_t decoded;
    mavlink_msg_propid_gyro_decode(&msg, &decoded);
    TEST_ASSERT_TRUE(decoded.time_usec == estimate.time_us);
    /* FLU -> FRD: x kept, y and z negated; standard deviations and ratios unsigned. */
    const float sign[3] = {1.0f, -1.0f, -1.0f};
    for (uint8_t axis = 0u; axis < 3u; ++axis) {
        ASSERT_SAME_FLOAT(sign[axis] * estimate.gyro_bias[axis], decoded.gyro_bias[axis]);
        ASSERT_SAME_FLOAT(estimate.gyro_bias_std[axis], decoded.gyro_bias_std[axis]);
        ASSERT_SAME_FLOAT(sign[axis] * estimate.body_rate[axis], decoded.body_rate[axis]);
        ASSERT_SAME_FLOAT(estimate.body_rate_std[axis], decoded.body_rate_std[axis]);
        ASSERT_SAME_FLOAT(sign[axis] * estimate.innovation[axis], decoded.innovation[axis]);
        ASSERT_SAME_FLOAT(estimate.innovation_test_ratio[axis],
                          decoded.innovation_test_ratio[axis]);
    }
    TEST_ASSERT_EQUAL_HEX32(PROPID_HEALTH_GATED | PROPID_HEALTH_COV_REPAIRED, decoded.health);
}

static void test_status_round_trip(void)
{
    uint8_t buf[PROPID_MAVLINK_STATUS_MAX_LEN];
    uint16_t len = 0u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK, propid_mavlink_pack_status(&sender, &estimate, &counters,
                                                                        buf, sizeof buf, &len));
    mavlink_message_t msg;
    TEST_ASSERT_EQUAL_UINT16(1u, mavlink_frames_parse(buf, len, &msg, 1u));
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_STATUS, msg.msgid);

    mavlink_propid_status_t decoded;
    mavlink_msg_propid_status_decode(&msg, &decoded);
    TEST_ASSERT_TRUE(decoded.time_usec == estimate.time_us);
    TEST_ASSERT_EQUAL_HEX32(estimate.health, decoded.health);
    TEST_ASSERT_EQUAL_UINT32(500000u, decoded.gyro_accepted);
    TEST_ASSERT_EQUAL_UINT32(250000u, decoded.rotor_accepted);
    TEST_ASSERT_EQUAL_UINT32(3u, decoded.axis_gated[0]);
    TEST_ASSERT_EQUAL_UINT32(4u, decoded.axis_gated[1]);
    TEST_ASSERT_EQUAL_UINT32(5u, decoded.axis_gated[2]);
    TEST_ASSERT_EQUAL_UINT32(1u, decoded.gate_reopened);
    TEST_ASSERT_EQUAL_UINT32(2u, decoded.cov_repairs);
    TEST_ASSERT_EQUAL_UINT32(6u, decoded.state_clamps);
    TEST_ASSERT_EQUAL_UINT32(7u, decoded.resyncs);
    uint32_t total = 0u;
    TEST_ASSERT_EQUAL_UINT32(0u, decoded.rejected[0]);
    for (uint8_t reason = 1u; reason < 16u; ++reason) {
        const uint32_t expected = (reason < PROPID_REJECT_SLOTS) ? 10u * reason : 0u;
        TEST_ASSERT_EQUAL_UINT32(expected, decoded.rejected[reason]);
        total += expected;
    }
    TEST_ASSERT_EQUAL_UINT32(total, decoded.rejected_total);
}

static void test_rejected_total_saturates(void)
{
    counters.rejected[1] = UINT32_MAX - 5u;
    counters.rejected[2] = 100u;
    uint8_t buf[PROPID_MAVLINK_STATUS_MAX_LEN];
    uint16_t len = 0u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK, propid_mavlink_pack_status(&sender, &estimate, &counters,
                                                                        buf, sizeof buf, &len));
    mavlink_message_t msg;
    TEST_ASSERT_EQUAL_UINT16(1u, mavlink_frames_parse(buf, len, &msg, 1u));
    TEST_ASSERT_EQUAL_UINT32(UINT32_MAX, mavlink_msg_propid_status_get_rejected_total(&msg));
}

static void test_report_three_frames_in_sequence(void)
{
    uint8_t buf[PROPID_MAVLINK_REPORT_MAX_LEN + GUARD_LEN];
    uint16_t len = 0u;
    memset(buf, MAVLINK_FRAMES_GUARD_BYTE, sizeof buf);
    sender.sequence = 254u; /* and the sequence number wraps */
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_report(&sender, &estimate, &counters, buf,
                                                     PROPID_MAVLINK_REPORT_MAX_LEN, &len));
    mavlink_frames_assert_untouched(&buf[PROPID_MAVLINK_REPORT_MAX_LEN], GUARD_LEN);
    TEST_ASSERT_EQUAL_UINT8(1u, sender.sequence);

    mavlink_message_t msgs[3];
    TEST_ASSERT_EQUAL_UINT16(3u, mavlink_frames_parse(buf, len, msgs, 3u));
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_STATUS, msgs[0].msgid);
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_GYRO, msgs[1].msgid);
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_COEFFICIENTS, msgs[2].msgid);
    TEST_ASSERT_EQUAL_UINT8(254u, msgs[0].seq);
    TEST_ASSERT_EQUAL_UINT8(255u, msgs[1].seq);
    TEST_ASSERT_EQUAL_UINT8(0u, msgs[2].seq);

    /* Without counters: two frames. */
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_report(&sender, &estimate, NULL, buf,
                                                     PROPID_MAVLINK_REPORT_MAX_LEN, &len));
    TEST_ASSERT_EQUAL_UINT16(2u, mavlink_frames_parse(buf, len, msgs, 3u));
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_GYRO, msgs[0].msgid);
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_COEFFICIENTS, msgs[1].msgid);
    TEST_ASSERT_EQUAL_UINT8(3u, sender.sequence);
}

static void fill_model(void)
{
    for (uint8_t axis = 0u; axis < 3u; ++axis) {
        estimate.disturbance_torque[axis] = 1.0e-4f * (float)(axis + 1u);
        estimate.disturbance_torque_std[axis] = 2.0e-5f * (float)(axis + 1u);
    }
    estimate.accel_bias = 0.25f;
    estimate.accel_bias_std = 0.05f;
    estimate.accel_innovation = -0.4f;
    estimate.torque_scale = 1.07f;
    estimate.torque_scale_std = 0.02f;
    estimate.rotor_delay_us = -12000;
    estimate.model_terms = PROPID_TERM_DISTURBANCE | PROPID_TERM_ACCEL | PROPID_TERM_TORQUE_SCALE |
                           PROPID_TERM_ESC_DELAY;
    counters.accel_accepted = 123456u;
    counters.accel_gated = 12u;
    counters.delay_overflows = 3u;
}

/* PROPID_MODEL: every field through the generated decoder, vectors and the z bias in FRD. */
static void test_model_round_trip_is_frd(void)
{
    fill_model();
    uint8_t buf[PROPID_MAVLINK_MODEL_MAX_LEN + GUARD_LEN];
    uint16_t len = 0u;
    memset(buf, MAVLINK_FRAMES_GUARD_BYTE, sizeof buf);
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_model(&sender, &estimate, &counters, buf,
                                                    PROPID_MAVLINK_MODEL_MAX_LEN, &len));
    mavlink_frames_assert_untouched(&buf[PROPID_MAVLINK_MODEL_MAX_LEN], GUARD_LEN);
    mavlink_message_t msg;
    TEST_ASSERT_EQUAL_UINT16(1u, mavlink_frames_parse(buf, len, &msg, 1u));
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_MODEL, msg.msgid);
    mavlink_propid_model_t decoded;
    mavlink_msg_propid_model_decode(&msg, &decoded);
    TEST_ASSERT_TRUE(decoded.time_usec == estimate.time_us);
    const float sign[3] = {1.0f, -1.0f, -1.0f};
    for (uint8_t axis = 0u; axis < 3u; ++axis) {
        ASSERT_SAME_FLOAT(sign[axis] * estimate.disturbance_torque[axis], decoded.disturbance_torque[axis]);
        ASSERT_SAME_FLOAT(estimate.disturbance_torque_std[axis], decoded.disturbance_torque_std[axis]);
    }
    ASSERT_SAME_FLOAT(-0.25f, decoded.accel_bias);
    ASSERT_SAME_FLOAT(0.05f, decoded.accel_bias_std);
    ASSERT_SAME_FLOAT(0.4f, decoded.accel_innovation);
    ASSERT_SAME_FLOAT(1.07f, decoded.torque_scale);
    ASSERT_SAME_FLOAT(0.02f, decoded.torque_scale_std);
    TEST_ASSERT_EQUAL_UINT32(123456u, decoded.accel_accepted);
    TEST_ASSERT_EQUAL_UINT32(12u, decoded.accel_gated);
    TEST_ASSERT_EQUAL_UINT32(3u, decoded.delay_overflows);
    TEST_ASSERT_EQUAL_INT32(-12000, decoded.esc_delay_us);
    TEST_ASSERT_EQUAL_HEX8(PROPID_MODEL_TERMS_DISTURBANCE | PROPID_MODEL_TERMS_ACCEL |
                               PROPID_MODEL_TERMS_TORQUE_SCALE | PROPID_MODEL_TERMS_ESC_DELAY,
                           decoded.terms);
    /* Without counters its counts are 0. */
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_model(&sender, &estimate, NULL, buf,
                                                    PROPID_MAVLINK_MODEL_MAX_LEN, &len));
    TEST_ASSERT_EQUAL_UINT16(1u, mavlink_frames_parse(buf, len, &msg, 1u));
    TEST_ASSERT_EQUAL_UINT32(0u, mavlink_msg_propid_model_get_accel_accepted(&msg));
}

/* With optional terms configured the report carries PROPID_MODEL after the status. */
static void test_report_with_model_terms_has_four_frames(void)
{
    fill_model();
    uint8_t buf[PROPID_MAVLINK_REPORT_MAX_LEN + GUARD_LEN];
    uint16_t len = 0u;
    memset(buf, MAVLINK_FRAMES_GUARD_BYTE, sizeof buf);
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_report(&sender, &estimate, &counters, buf,
                                                     PROPID_MAVLINK_REPORT_MAX_LEN, &len));
    mavlink_frames_assert_untouched(&buf[PROPID_MAVLINK_REPORT_MAX_LEN], GUARD_LEN);
    mavlink_message_t msgs[4];
    TEST_ASSERT_EQUAL_UINT16(4u, mavlink_frames_parse(buf, len, msgs, 4u));
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_STATUS, msgs[0].msgid);
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_MODEL, msgs[1].msgid);
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_GYRO, msgs[2].msgid);
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_COEFFICIENTS, msgs[3].msgid);
    TEST_ASSERT_EQUAL_UINT8(204u, sender.sequence);
    /* A filter's own estimate says which terms it runs with. */
    static propid_filter_t filter;
    propid_config_t config;
    propid_config_default(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(&config, 4u, 0.05f, 0.0f, 1.0f, 2.3e-8f, 7.8e-10f));
    propid_config_set_inertia_diag(&config, 1.4e-5f, 1.4e-5f, 2.9e-5f);
    config.disturbance_torque = 1u;
    config.rotor_inertia[0] = 1.0e-8f;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &estimate));
    TEST_ASSERT_EQUAL_HEX8(PROPID_TERM_DISTURBANCE | PROPID_TERM_ROTOR_INERTIA, estimate.model_terms);
    TEST_ASSERT_EQUAL_INT32(0, estimate.rotor_delay_us);
}

/* Every size below the frame's is rejected without touching the buffer or sequence. */
static void test_buffer_too_small_writes_nothing(void)
{
    uint8_t buf[PROPID_MAVLINK_REPORT_MAX_LEN];
    uint16_t full = 0u;
    propid_mavlink_sender_t probe = sender;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_report(&probe, &estimate, &counters, buf, sizeof buf,
                                                     &full));
    for (uint16_t size = 0u; size < full; ++size) {
        uint16_t len = 123u;
        memset(buf, MAVLINK_FRAMES_GUARD_BYTE, sizeof buf);
        TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_BUFFER,
                              propid_mavlink_pack_report(&sender, &estimate, &counters, buf, size,
                                                         &len));
        TEST_ASSERT_EQUAL_UINT16(0u, len);
        TEST_ASSERT_EQUAL_UINT8(200u, sender.sequence);
        mavlink_frames_assert_untouched(buf, sizeof buf);
    }
    uint16_t single = 0u;
    probe = sender;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_gyro(&probe, &estimate, buf, sizeof buf, &single));
    for (uint16_t size = 0u; size < single; ++size) {
        uint16_t len = 123u;
        memset(buf, MAVLINK_FRAMES_GUARD_BYTE, sizeof buf);
        TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_BUFFER,
                              propid_mavlink_pack_gyro(&sender, &estimate, buf, size, &len));
        TEST_ASSERT_EQUAL_UINT16(0u, len);
        TEST_ASSERT_EQUAL_UINT8(200u, sender.sequence);
        mavlink_frames_assert_untouched(buf, sizeof buf);
    }
    /* Exactly the frame's size is enough. */
    uint16_t len = 0u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_gyro(&sender, &estimate, buf, single, &len));
    TEST_ASSERT_EQUAL_UINT16(single, len);
}

/* A corrupted byte must fail the checksum: the parser counts an error and never
 * delivers the frame; the next intact frame is parsed again. */
static void test_corrupted_frame_fails_crc(void)
{
    uint8_t buf[PROPID_MAVLINK_COEFFICIENTS_MAX_LEN];
    uint16_t len = 0u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_coefficients(&sender, &estimate, buf, sizeof buf, &len));
    buf[20] ^= 0x40u;
    mavlink_message_t msg;
    const uint8_t errors_before = mavlink_frames_parse_errors();
    for (uint16_t i = 0u; i < len; ++i) {
        TEST_ASSERT_NOT_EQUAL(MAVLINK_FRAMING_OK, mavlink_frames_parse_byte(buf[i], &msg));
    }
    TEST_ASSERT_EQUAL_UINT8((uint8_t)(errors_before + 1u), mavlink_frames_parse_errors());

    buf[20] ^= 0x40u;
    TEST_ASSERT_EQUAL_UINT16(1u, mavlink_frames_parse(buf, len, &msg, 1u));
}

static void test_bad_arguments_rejected(void)
{
    uint8_t buf[PROPID_MAVLINK_REPORT_MAX_LEN];
    uint16_t len = 99u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_NULL,
                          propid_mavlink_pack_coefficients(NULL, &estimate, buf, sizeof buf, &len));
    TEST_ASSERT_EQUAL_UINT16(0u, len);
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_NULL,
                          propid_mavlink_pack_coefficients(&sender, NULL, buf, sizeof buf, &len));
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_NULL,
                          propid_mavlink_pack_gyro(&sender, &estimate, NULL, sizeof buf, &len));
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_NULL,
                          propid_mavlink_pack_gyro(&sender, &estimate, buf, sizeof buf, NULL));
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_NULL,
                          propid_mavlink_pack_status(&sender, &estimate, NULL, buf, sizeof buf, &len));

    estimate.rotor_count = 0u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_ROTOR_COUNT,
                          propid_mavlink_pack_report(&sender, &estimate, &counters, buf, sizeof buf,
                                                     &len));
    estimate.rotor_count = 9u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_ROTOR_COUNT,
                          propid_mavlink_pack_coefficients(&sender, &estimate, buf, sizeof buf, &len));
    estimate.rotor_count = 4u;
    sender.system_id = 0u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_SYSTEM_ID,
                          propid_mavlink_pack_gyro(&sender, &estimate, buf, sizeof buf, &len));
    TEST_ASSERT_EQUAL_UINT8(200u, sender.sequence);
    TEST_ASSERT_EQUAL_STRING("PROPID_MAVLINK_ERR_BUFFER",
                             propid_mavlink_status_name(PROPID_MAVLINK_ERR_BUFFER));
}

static void init_quad(propid_filter_t *filter)
{
    propid_config_t config;
    propid_config_default(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(&config, 4u, 0.043f, 0.0f, 1.0f,
                                                                 2.3e-8f, 7.8e-10f));
    propid_config_set_inertia_diag(&config, 1.43e-5f, 1.43e-5f, 2.89e-5f);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(filter, &config));
}

static void test_reset_command_decisions(void)
{
    static propid_filter_t filter; /* static: keep the test's stack small */
    memset(&filter, 0, sizeof filter);
    TEST_ASSERT_EQUAL_UINT8(PROPID_MAVLINK_RESULT_FAILED, propid_mavlink_execute_reset(NULL, -1.0f));
    TEST_ASSERT_EQUAL_UINT8(PROPID_MAVLINK_RESULT_FAILED,
                            propid_mavlink_execute_reset(&filter, -1.0f));

    init_quad(&filter);
    /* Move rotors 1 and 2 away from their prior, then reset rotor 2 only. */
    const uint8_t kf1 = propid_index_thrust_coeff(1u);
    const uint8_t kf2 = propid_index_thrust_coeff(2u);
    /* Set and read per rotor: the filter keeps the kf in their torque basis
     * (equal up to the rounding of the maps between the bases). */
    const float prior_var = filter.core.cov[propid_cov_index(kf2, kf2)];
    propid_coeff_flip(&filter.derived, &filter.config, &filter.core, 1);
    filter.core.state[kf1] = 1.2f;
    filter.core.state[kf2] = 1.3f;
    filter.core.cov[propid_cov_index(kf2, kf2)] = 0.25f * prior_var;
    propid_coeff_flip(&filter.derived, &filter.config, &filter.core, 0);
    TEST_ASSERT_EQUAL_UINT8(PROPID_MAVLINK_RESULT_ACCEPTED,
                            propid_mavlink_execute_reset(&filter, 2.0f));
    propid_core_t view = per_rotor_core(&filter);
    TEST_ASSERT_FLOAT_WITHIN(1e-6f, 1.0f, view.state[kf2]);
    TEST_ASSERT_FLOAT_WITHIN(1e-5f * prior_var, prior_var, view.cov[propid_cov_index(kf2, kf2)]);
    TEST_ASSERT_FLOAT_WITHIN(1e-6f, 1.2f, view.state[kf1]);

    propid_coeff_flip(&filter.derived, &filter.config, &filter.core, 1);
    filter.core.state[kf2] = 0.7f;
    propid_coeff_flip(&filter.derived, &filter.config, &filter.core, 0);
    TEST_ASSERT_EQUAL_UINT8(PROPID_MAVLINK_RESULT_ACCEPTED,
                            propid_mavlink_execute_reset(&filter, -1.0f));
    view = per_rotor_core(&filter);
    TEST_ASSERT_FLOAT_WITHIN(1e-6f, 1.0f, view.state[kf2]);
    TEST_ASSERT_FLOAT_WITHIN(1e-6f, 1.0f, view.state[kf1]);

    const float nan = NAN;
    TEST_ASSERT_EQUAL_UINT8(PROPID_MAVLINK_RESULT_DENIED, propid_mavlink_execute_reset(&filter, 4.0f));
    TEST_ASSERT_EQUAL_UINT8(PROPID_MAVLINK_RESULT_DENIED, propid_mavlink_execute_reset(&filter, 1.5f));
    TEST_ASSERT_EQUAL_UINT8(PROPID_MAVLINK_RESULT_DENIED, propid_mavlink_execute_reset(&filter, -2.0f));
    TEST_ASSERT_EQUAL_UINT8(PROPID_MAVLINK_RESULT_DENIED, propid_mavlink_execute_reset(&filter, 300.0f));
    TEST_ASSERT_EQUAL_UINT8(PROPID_MAVLINK_RESULT_DENIED, propid_mavlink_execute_reset(&filter, nan));
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_coefficients_round_trip);
    RUN_TEST(test_eight_rotors_round_trip);
    RUN_TEST(test_gyro_round_trip_is_frd);
    RUN_TEST(test_status_round_trip);
    RUN_TEST(test_rejected_total_saturates);
    RUN_TEST(test_report_three_frames_in_sequence);
    RUN_TEST(test_model_round_trip_is_frd);
    RUN_TEST(test_report_with_model_terms_has_four_frames);
    RUN_TEST(test_buffer_too_small_writes_nothing);
    RUN_TEST(test_corrupted_frame_fails_crc);
    RUN_TEST(test_bad_arguments_rejected);
    RUN_TEST(test_reset_command_decisions);
    return UNITY_END();
}
