/* Test helper of the MAVLink packer tests; see mavlink_frames.h. */
#include "mavlink_frames.h"

#include "unity.h"

void mavlink_frames_reset(void)
{
    mavlink_reset_channel_status(MAVLINK_COMM_0);
}

uint16_t mavlink_frames_parse(const uint8_t *bytes, uint16_t len, mavlink_message_t *msgs,
                              uint16_t max_msgs)
{
    mavlink_message_t msg;
    mavlink_status_t status;
    uint16_t frames = 0u;
    for (uint16_t i = 0u; i < len; ++i) {
        const uint8_t result = mavlink_parse_char(MAVLINK_COMM_0, bytes[i], &msg, &status);
        if (result == MAVLINK_FRAMING_OK) {
            TEST_ASSERT_TRUE(frames < max_msgs);
            msgs[frames++] = msg;
        }
        TEST_ASSERT_NOT_EQUAL(MAVLINK_FRAMING_BAD_CRC, result);
    }
    return frames;
}

uint8_t mavlink_frames_parse_byte(uint8_t byte, mavlink_message_t *msg)
{
    mavlink_status_t status;
    return mavlink_parse_char(MAVLINK_COMM_0, byte, msg, &status);
}

uint8_t mavlink_frames_parse_errors(void)
{
    return mavlink_get_channel_status(MAVLINK_COMM_0)->parse_error;
}

void mavlink_frames_assert_untouched(const uint8_t *bytes, size_t len)
{
    for (size_t i = 0u; i < len; ++i) {
        TEST_ASSERT_EQUAL_HEX8(MAVLINK_FRAMES_GUARD_BYTE, bytes[i]);
    }
}
