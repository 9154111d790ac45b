/*
 * Test helper shared by the MAVLink packer tests (test_mavlink*.c): decoding
 * packed bytes with the generated library's own byte parser, and checking a
 * buffer the packer must have left untouched.
 *
 * The generated helpers are static inline, so every translation unit has its
 * own parser state: a test that parses must do all of it through these
 * functions (reset, bytes, error count), never mavlink_parse_char directly.
 */
#ifndef PROPID_TEST_MAVLINK_FRAMES_H
#define PROPID_TEST_MAVLINK_FRAMES_H

#include <stddef.h>
#include <stdint.h>

#include "mavlink/propid/mavlink.h"

/* The byte a test fills a buffer with before packing into it. */
#define MAVLINK_FRAMES_GUARD_BYTE 0xA5u

/* Parser state back to idle, error count to zero (call it from setUp). */
void mavlink_frames_reset(void);

/* Feeds len bytes to the parser; the complete frames that passed the checksum
 * go to msgs (at most max_msgs: more fails the test). Returns their number. */
uint16_t mavlink_frames_parse(const uint8_t *bytes, uint16_t len, mavlink_message_t *msgs,
                              uint16_t max_msgs);

/* One byte to the same parser; mavlink_parse_char's result. */
uint8_t mavlink_frames_parse_byte(uint8_t byte, mavlink_message_t *msg);

/* Frames the parser has rejected so far (checksum and framing errors). */
uint8_t mavlink_frames_parse_errors(void);

/* Fails the test unless every one of the len bytes is MAVLINK_FRAMES_GUARD_BYTE. */
void mavlink_frames_assert_untouched(const uint8_t *bytes, size_t len);

#endif
