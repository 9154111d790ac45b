/*
 * propid MAVLink report packer (optional library `propid_mavlink`).
 *
 * Turns a propid_estimate_t (+ counters) into MAVLink 2 frames of the propid
 * dialect (firmware/mavlink/propid.xml) in a buffer the caller provides, and
 * executes the dialect's reset command. It allocates nothing, does no I/O and
 * keeps no hidden state: the caller owns the sender (ids + sequence number)
 * and writes the returned bytes to its own link (UART, UDP, USB...).
 *
 * Vectors leave in MAVLink's body frame FRD (the filter works in FLU): the
 * y and z components of gyro bias, body rate and innovation change sign here.
 *
 *     static propid_mavlink_sender_t sender = { .system_id = 1, .component_id = 1 };
 *     uint8_t frame[PROPID_MAVLINK_REPORT_MAX_LEN];
 *     uint16_t len;
 *     propid_get_estimate(&filter, &estimate);
 *     propid_get_counters(&filter, &counters);
 *     if (propid_mavlink_pack_report(&sender, &estimate, &counters,
 *                                    frame, sizeof frame, &len) == PROPID_MAVLINK_OK)
 *         uart_write(frame, len);
 */
#ifndef PROPID_MAVLINK_H
#define PROPID_MAVLINK_H

#include <stdint.h>

#include "propid/propid.h"
#include "propid/propid_damage.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum {
    PROPID_MAVLINK_OK = 0,
    PROPID_MAVLINK_ERR_NULL = -1,          /* a pointer argument was NULL */
    PROPID_MAVLINK_ERR_BUFFER = -2,        /* the frame does not fit in buf_size: nothing written */
    PROPID_MAVLINK_ERR_ROTOR_COUNT = -3,   /* estimate->rotor_count is 0 or > PROPID_MAVLINK_MAX_ROTORS */
    PROPID_MAVLINK_ERR_SYSTEM_ID = -4,     /* sender->system_id 0 is the broadcast id, not a sender */
    PROPID_MAVLINK_ERR_NO_DETECTION = -5,  /* the damage detector has no detection to report */
} propid_mavlink_status_t;

/* The dialect's arrays hold 8 rotors, whatever PROPID_MAX_ROTORS is. */
#define PROPID_MAVLINK_MAX_ROTORS 8u

/* MAVLink 2 ids of the dialect (the generated headers define the same values). */
#define PROPID_MAVLINK_MSG_ID_COEFFICIENTS 53000u
#define PROPID_MAVLINK_MSG_ID_GYRO 53001u
#define PROPID_MAVLINK_MSG_ID_STATUS 53002u
#define PROPID_MAVLINK_MSG_ID_MODEL 53004u
#define PROPID_MAVLINK_MSG_ID_DAMAGE 53003u
#define PROPID_MAVLINK_MSG_ID_STATUSTEXT 253u
#define PROPID_MAVLINK_CMD_RESET 53000u

/* Largest frame of each message: 10 header + payload + 2 checksum bytes, unsigned.
 * MAVLink 2 trims trailing zero bytes, so real frames may be shorter. */
#define PROPID_MAVLINK_COEFFICIENTS_MAX_LEN (12u + 145u)
#define PROPID_MAVLINK_GYRO_MAX_LEN (12u + 84u)
#define PROPID_MAVLINK_STATUS_MAX_LEN (12u + 116u)
#define PROPID_MAVLINK_MODEL_MAX_LEN (12u + 69u)
#define PROPID_MAVLINK_DAMAGE_MAX_LEN (12u + 15u)
#define PROPID_MAVLINK_STATUSTEXT_MAX_LEN (12u + 54u)
#define PROPID_MAVLINK_DAMAGE_ALERT_MAX_LEN                                        \
    (PROPID_MAVLINK_DAMAGE_MAX_LEN + PROPID_MAVLINK_STATUSTEXT_MAX_LEN)
#define PROPID_MAVLINK_REPORT_MAX_LEN                                              \
    (PROPID_MAVLINK_COEFFICIENTS_MAX_LEN + PROPID_MAVLINK_GYRO_MAX_LEN +           \
     PROPID_MAVLINK_STATUS_MAX_LEN + PROPID_MAVLINK_MODEL_MAX_LEN)

/* MAV_SEVERITY of the damage STATUSTEXT (common.xml): CRITICAL, a ground station
 * shows and speaks it. */
#define PROPID_MAVLINK_SEVERITY_CRITICAL 2u

/* MAV_RESULT values returned by propid_mavlink_execute_reset (common.xml). */
#define PROPID_MAVLINK_RESULT_ACCEPTED 0u
#define PROPID_MAVLINK_RESULT_DENIED 2u
#define PROPID_MAVLINK_RESULT_FAILED 4u

/* Who sends, and the running sequence number (incremented once per frame). */
typedef struct {
    uint8_t system_id;      /* 1..255 */
    uint8_t component_id;   /* e.g. 1 = MAV_COMP_ID_AUTOPILOT1 */
    uint8_t sequence;       /* sequence number of the next frame */
} propid_mavlink_sender_t;

/* Each packer writes one frame to buf and its length to *frame_len. On any error
 * nothing is written to buf, *frame_len is 0 (when not NULL) and the sequence
 * number does not move. */

/* PROPID_COEFFICIENTS: kf, km, their std, convergence masks. */
propid_mavlink_status_t propid_mavlink_pack_coefficients(propid_mavlink_sender_t *sender,
                                                         const propid_estimate_t *estimate,
                                                         uint8_t *buf, uint16_t buf_size,
                                                         uint16_t *frame_len);

/* PROPID_GYRO: gyro bias, body rate, innovation (FRD), health. */
propid_mavlink_status_t propid_mavlink_pack_gyro(propid_mavlink_sender_t *sender,
                                                 const propid_estimate_t *estimate,
                                                 uint8_t *buf, uint16_t buf_size,
                                                 uint16_t *frame_len);

/* PROPID_STATUS: health (from estimate) and counters. */
propid_mavlink_status_t propid_mavlink_pack_status(propid_mavlink_sender_t *sender,
                                                   const propid_estimate_t *estimate,
                                                   const propid_counters_t *counters,
                                                   uint8_t *buf, uint16_t buf_size,
                                                   uint16_t *frame_len);

/* PROPID_MODEL: the optional terms (estimate->model_terms), their estimates and
 * the telemetry delay; counters may be NULL (its counts are then 0). */
propid_mavlink_status_t propid_mavlink_pack_model(propid_mavlink_sender_t *sender,
                                                  const propid_estimate_t *estimate,
                                                  const propid_counters_t *counters,
                                                  uint8_t *buf, uint16_t buf_size,
                                                  uint16_t *frame_len);

/* The frames back to back, in the order PROPID_STATUS (only when counters is not
 * NULL), PROPID_MODEL (only when estimate->model_terms is not 0), PROPID_GYRO,
 * PROPID_COEFFICIENTS. All or nothing: if the whole report does not fit, nothing
 * is written. */
propid_mavlink_status_t propid_mavlink_pack_report(propid_mavlink_sender_t *sender,
                                                   const propid_estimate_t *estimate,
                                                   const propid_counters_t *counters,
                                                   uint8_t *buf, uint16_t buf_size,
                                                   uint16_t *frame_len);

/* PROPID_DAMAGE of the detector's latest detection: its time, the isolated rotor
 * (1-based on the wire), the detection count and the damaged-rotor mask.
 * PROPID_MAVLINK_ERR_NO_DETECTION when the detector has none (or its fields are
 * out of range: rotor count above 8, rotor not below it). */
propid_mavlink_status_t propid_mavlink_pack_damage(propid_mavlink_sender_t *sender,
                                                   const propid_damage_t *detector,
                                                   uint8_t *buf, uint16_t buf_size,
                                                   uint16_t *frame_len);

/* The alert to send once per detection: PROPID_DAMAGE, then a STATUSTEXT of
 * severity CRITICAL, "propid: rotor N damaged, re-identifying" (N 1-based).
 * All or nothing, like the report. */
propid_mavlink_status_t propid_mavlink_pack_damage_alert(propid_mavlink_sender_t *sender,
                                                         const propid_damage_t *detector,
                                                         uint8_t *buf, uint16_t buf_size,
                                                         uint16_t *frame_len);

/* Execute MAV_CMD_PROPID_RESET with its param1 (rotor index, or -1 for all) on
 * filter. Returns the MAV_RESULT to acknowledge with: ACCEPTED, DENIED (param1
 * not -1 nor an integral rotor index below rotor_count) or FAILED (filter NULL
 * or not initialised). */
uint8_t propid_mavlink_execute_reset(propid_filter_t *filter, float rotor_param);

/* Short constant name of a packer status, e.g. "PROPID_MAVLINK_ERR_BUFFER". */
const char *propid_mavlink_status_name(propid_mavlink_status_t status);

#ifdef __cplusplus
}
#endif

#endif /* PROPID_MAVLINK_H */
