/*
 * The damage packers of propid_mavlink: PROPID_DAMAGE and the CRITICAL
 * STATUSTEXT a ground station shows, decoded back with the generated library's
 * own byte parser (checksum, 1-based rotor, mask); all-or-nothing on a short
 * buffer; no detection / bad arguments rejected with nothing written.
 */
#include <string.h>

#include "mavlink_frames.h"
#include "propid/propid_damage.h"
#include "propid/propid_mavlink.h"
#include "unity.h"

static propid_mavlink_sender_t sender;
static propid_damage_t detector;

void setUp(void)
{
    memset(&detector, 0, sizeof detector);
    detector.rotor_count = 6u;
    detector.detections = 2u;
    detector.last_rotor = 4;                /* rotor 5 on the wire */
    detector.damaged_mask = (1u << 4) | 1u; /* rotors 1 and 5 */
    detector.last_detection_us = 4123456789ull;
    sender.system_id = 3u;
    sender.component_id = 1u;
    sender.sequence = 254u;
    mavlink_frames_reset();
}

void tearDown(void) {}

/* Decoded into a struct (the generated getters read the packed payload in place,
 * which is misaligned inside an array of messages). */
static void assert_damage_fields(const mavlink_message_t *msg)
{
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_PROPID_DAMAGE, msg->msgid);
    TEST_ASSERT_EQUAL_UINT8(3u, msg->sysid);
    mavlink_propid_damage_t decoded;
    mavlink_msg_propid_damage_decode(msg, &decoded);
    TEST_ASSERT_EQUAL_UINT64(4123456789ull, decoded.time_usec);
    TEST_ASSERT_EQUAL_UINT8(5u, decoded.rotor);
    TEST_ASSERT_EQUAL_UINT32(2u, decoded.detections);
    TEST_ASSERT_EQUAL_HEX16(0x11u, decoded.damaged_mask);
}

static void test_damage_round_trip(void)
{
    uint8_t buf[PROPID_MAVLINK_DAMAGE_MAX_LEN];
    uint16_t len = 0u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_damage(&sender, &detector, buf, sizeof buf, &len));
    TEST_ASSERT_TRUE(len > 0u && len <= PROPID_MAVLINK_DAMAGE_MAX_LEN);
    mavlink_message_t msg;
    TEST_ASSERT_EQUAL_UINT16(1u, mavlink_frames_parse(buf, len, &msg, 1u));
    assert_damage_fields(&msg);
    TEST_ASSERT_EQUAL_UINT8(254u, msg.seq);
    TEST_ASSERT_EQUAL_UINT8(255u, sender.sequence);
}

static void test_alert_is_damage_then_critical_statustext(void)
{
    uint8_t buf[PROPID_MAVLINK_DAMAGE_ALERT_MAX_LEN];
    uint16_t len = 0u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                          propid_mavlink_pack_damage_alert(&sender, &detector, buf, sizeof buf, &len));
    mavlink_message_t msgs[2];
    TEST_ASSERT_EQUAL_UINT16(2u, mavlink_frames_parse(buf, len, msgs, 2u));
    assert_damage_fields(&msgs[0]);
    TEST_ASSERT_EQUAL_UINT32(MAVLINK_MSG_ID_STATUSTEXT, msgs[1].msgid);
    mavlink_statustext_t status;
    mavlink_msg_statustext_decode(&msgs[1], &status);
    TEST_ASSERT_EQUAL_UINT8(MAV_SEVERITY_CRITICAL, status.severity);
    char text[MAVLINK_MSG_STATUSTEXT_FIELD_TEXT_LEN + 1] = {0};
    memcpy(text, status.text, MAVLINK_MSG_STATUSTEXT_FIELD_TEXT_LEN);
    TEST_ASSERT_EQUAL_STRING("propid: rotor 5 damaged, re-identifying", text);
    /* sequence numbers run on across the two frames and wrap */
    TEST_ASSERT_EQUAL_UINT8(254u, msgs[0].seq);
    TEST_ASSERT_EQUAL_UINT8(255u, msgs[1].seq);
    TEST_ASSERT_EQUAL_UINT8(0u, sender.sequence);
}

static void test_every_rotor_named_in_the_text(void)
{
    detector.rotor_count = 8u;
    for (int8_t rotor = 0; rotor < 8; ++rotor) {
        detector.last_rotor = rotor;
        uint8_t buf[PROPID_MAVLINK_DAMAGE_ALERT_MAX_LEN];
        uint16_t len = 0u;
        TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_OK,
                              propid_mavlink_pack_damage_alert(&sender, &detector, buf, sizeof buf, &len));
        mavlink_message_t msgs[2];
        TEST_ASSERT_EQUAL_UINT16(2u, mavlink_frames_parse(buf, len, msgs, 2u));
        mavlink_propid_damage_t damage;
        mavlink_msg_propid_damage_decode(&msgs[0], &damage);
        TEST_ASSERT_EQUAL_UINT8((uint8_t)(rotor + 1), damage.rotor);
        mavlink_statustext_t status;
        mavlink_msg_statustext_decode(&msgs[1], &status);
        TEST_ASSERT_EQUAL_CHAR((char)('1' + rotor), status.text[14]);
    }
}

static void test_short_buffer_writes_nothing(void)
{
    uint8_t buf[PROPID_MAVLINK_DAMAGE_ALERT_MAX_LEN];
    memset(buf, MAVLINK_FRAMES_GUARD_BYTE, sizeof buf);
    uint16_t len = 77u;
    /* room for PROPID_DAMAGE but not the STATUSTEXT: the alert writes nothing */
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_BUFFER,
                          propid_mavlink_pack_damage_alert(&sender, &detector, buf,
                                                           PROPID_MAVLINK_DAMAGE_MAX_LEN + 10u, &len));
    TEST_ASSERT_EQUAL_UINT16(0u, len);
    TEST_ASSERT_EQUAL_UINT8(254u, sender.sequence);
    mavlink_frames_assert_untouched(buf, sizeof buf);
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_BUFFER,
                          propid_mavlink_pack_damage(&sender, &detector, buf, 5u, &len));
    TEST_ASSERT_EQUAL_HEX8(MAVLINK_FRAMES_GUARD_BYTE, buf[0]);
}

static void test_no_detection_and_bad_arguments_rejected(void)
{
    uint8_t buf[PROPID_MAVLINK_DAMAGE_ALERT_MAX_LEN];
    uint16_t len = 9u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_NULL,
                          propid_mavlink_pack_damage(&sender, NULL, buf, sizeof buf, &len));
    TEST_ASSERT_EQUAL_UINT16(0u, len);
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_NULL,
                          propid_mavlink_pack_damage_alert(NULL, &detector, buf, sizeof buf, &len));
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_NULL,
                          propid_mavlink_pack_damage_alert(&sender, &detector, NULL, sizeof buf, &len));
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_NULL,
                          propid_mavlink_pack_damage(&sender, &detector, buf, sizeof buf, NULL));

    propid_damage_t none;
    memset(&none, 0, sizeof none);
    none.rotor_count = 4u;
    none.last_rotor = -1; /* as propid_damage_init leaves it */
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_NO_DETECTION,
                          propid_mavlink_pack_damage_alert(&sender, &none, buf, sizeof buf, &len));
    detector.last_rotor = 6; /* not below rotor_count 6 */
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_NO_DETECTION,
                          propid_mavlink_pack_damage(&sender, &detector, buf, sizeof buf, &len));
    detector.last_rotor = 4;
    detector.rotor_count = 9u; /* more than the dialect carries */
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_NO_DETECTION,
                          propid_mavlink_pack_damage(&sender, &detector, buf, sizeof buf, &len));
    detector.rotor_count = 6u;
    sender.system_id = 0u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_SYSTEM_ID,
                          propid_mavlink_pack_damage(&sender, &detector, buf, sizeof buf, &len));
    TEST_ASSERT_EQUAL_UINT8(254u, sender.sequence);
    TEST_ASSERT_EQUAL_STRING("PROPID_MAVLINK_ERR_NO_DETECTION",
                             propid_mavlink_status_name(PROPID_MAVLINK_ERR_NO_DETECTION));
}

/* A freshly initialised detector has nothing to report. */
static void test_detector_after_init_has_nothing_to_report(void)
{
    static propid_filter_t filter;
    propid_config_t config;
    propid_config_default(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(&config, 4u, 0.043f, 0.0f, 1.0f,
                                                                 2.3e-8f, 7.8e-10f));
    propid_config_set_inertia_diag(&config, 1.43e-5f, 1.43e-5f, 2.89e-5f);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    propid_damage_config_t dc;
    propid_damage_config_default(&dc);
    propid_damage_t fresh;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_damage_init(&fresh, &dc, &filter));
    uint8_t buf[PROPID_MAVLINK_DAMAGE_ALERT_MAX_LEN];
    uint16_t len = 1u;
    TEST_ASSERT_EQUAL_INT(PROPID_MAVLINK_ERR_NO_DETECTION,
                          propid_mavlink_pack_damage_alert(&sender, &fresh, buf, sizeof buf, &len));
    TEST_ASSERT_EQUAL_UINT16(0u, len);
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_damage_round_trip);
    RUN_TEST(test_alert_is_damage_then_critical_statustext);
    RUN_TEST(test_every_rotor_named_in_the_text);
    RUN_TEST(test_short_buffer_writes_nothing);
    RUN_TEST(test_no_detection_and_bad_arguments_rejected);
    RUN_TEST(test_detector_after_init_has_nothing_to_report);
    return UNITY_END();
}
