/*
 * MAVLink 2 report packer for the propid dialect (see propid_mavlink.h).
 *
 * Each frame is built in a mavlink_message_t on the stack with the generated
 * *_pack_status() functions (they take our own sequence counter instead of
 * the generated library's hidden per-channel globals), its final length is
 * checked against the caller's buffer, and only then is it serialised.
 */
#include "propid/propid_mavlink.h"

#include <stddef.h>

/* We never sign frames and need none of the generated library's trigonometry:
 * leave both out of the firmware image (saves SHA-256 code and tables). */
#define MAVLINK_NO_SIGN_PACKET
#define MAVLINK_NO_CONVERSION_HELPERS
#include "mavlink/propid/mavlink.h"

_Static_assert(MAVLINK_MSG_ID_PROPID_COEFFICIENTS == PROPID_MAVLINK_MSG_ID_COEFFICIENTS,
               "dialect id");
_Static_assert(MAVLINK_MSG_ID_PROPID_GYRO == PROPID_MAVLINK_MSG_ID_GYRO, "dialect id");
_Static_assert(MAVLINK_MSG_ID_PROPID_STATUS == PROPID_MAVLINK_MSG_ID_STATUS, "dialect id");
_Static_assert(MAV_CMD_PROPID_RESET == PROPID_MAVLINK_CMD_RESET, "dialect command");
_Static_assert(MAVLINK_NUM_NON_PAYLOAD_BYTES + MAVLINK_MSG_ID_PROPID_COEFFICIENTS_LEN ==
                   PROPID_MAVLINK_COEFFICIENTS_MAX_LEN,
               "coefficients frame size");
_Static_assert(MAVLINK_NUM_NON_PAYLOAD_BYTES + MAVLINK_MSG_ID_PROPID_GYRO_LEN ==
                   PROPID_MAVLINK_GYRO_MAX_LEN,
               "gyro frame size");
_Static_assert(MAVLINK_NUM_NON_PAYLOAD_BYTES + MAVLINK_MSG_ID_PROPID_STATUS_LEN ==
                   PROPID_MAVLINK_STATUS_MAX_LEN,
               "status frame size");
_Static_assert(MAVLINK_MSG_ID_PROPID_MODEL == PROPID_MAVLINK_MSG_ID_MODEL, "dialect id");
_Static_assert(MAVLINK_MSG_ID_PROPID_DAMAGE == PROPID_MAVLINK_MSG_ID_DAMAGE, "dialect id");
_Static_assert(MAVLINK_MSG_ID_STATUSTEXT == PROPID_MAVLINK_MSG_ID_STATUSTEXT, "common id");
_Static_assert(MAVLINK_NUM_NON_PAYLOAD_BYTES + MAVLINK_MSG_ID_PROPID_DAMAGE_LEN ==
                   PROPID_MAVLINK_DAMAGE_MAX_LEN,
               "damage frame size");
_Static_assert(MAVLINK_NUM_NON_PAYLOAD_BYTES + MAVLINK_MSG_ID_STATUSTEXT_LEN ==
                   PROPID_MAVLINK_STATUSTEXT_MAX_LEN,
               "statustext frame size");
_Static_assert(MAV_SEVERITY_CRITICAL == PROPID_MAVLINK_SEVERITY_CRITICAL, "MAV_SEVERITY value");
_Static_assert(PROPID_MAX_ROTORS <= 9, "the damage text writes the rotor number as one digit");
_Static_assert(MAVLINK_NUM_NON_PAYLOAD_BYTES + MAVLINK_MSG_ID_PROPID_MODEL_LEN ==
                   PROPID_MAVLINK_MODEL_MAX_LEN,
               "model frame size");
_Static_assert(PROPID_TERM_DISTURBANCE == PROPID_MODEL_TERMS_DISTURBANCE &&
                   PROPID_TERM_ACCEL == PROPID_MODEL_TERMS_ACCEL &&
                   PROPID_TERM_TORQUE_SCALE == PROPID_MODEL_TERMS_TORQUE_SCALE &&
                   PROPID_TERM_ROTOR_INERTIA == PROPID_MODEL_TERMS_ROTOR_INERTIA &&
                   PROPID_TERM_ESC_DELAY == PROPID_MODEL_TERMS_ESC_DELAY &&
                   PROPID_TERM_AERO_DAMPING == PROPID_MODEL_TERMS_AERO_DAMPING,
               "model term bits mirror propid.h");
_Static_assert(PROPID_REJECT_SLOTS <= 16, "PROPID_STATUS.rejected holds 16 reasons");
_Static_assert(MAV_RESULT_ACCEPTED == PROPID_MAVLINK_RESULT_ACCEPTED &&
                   MAV_RESULT_DENIED == PROPID_MAVLINK_RESULT_DENIED &&
                   MAV_RESULT_FAILED == PROPID_MAVLINK_RESULT_FAILED,
               "MAV_RESULT values");
_Static_assert(PROPID_HEALTH_NO_ROTOR_DATA == PROPID_HEALTH_FLAGS_NO_ROTOR_DATA &&
                   PROPID_HEALTH_ROTOR_STALE == PROPID_HEALTH_FLAGS_ROTOR_STALE &&
                   PROPID_HEALTH_GATED == PROPID_HEALTH_FLAGS_GATED &&
                   PROPID_HEALTH_COV_REPAIRED == PROPID_HEALTH_FLAGS_COV_REPAIRED &&
                   PROPID_HEALTH_STATE_CLAMPED == PROPID_HEALTH_FLAGS_STATE_CLAMPED &&
                   PROPID_HEALTH_GATE_REOPENED == PROPID_HEALTH_FLAGS_GATE_REOPENED &&
                   PROPID_HEALTH_ALL_CONVERGED == PROPID_HEALTH_FLAGS_ALL_CONVERGED &&
                   PROPID_HEALTH_TIME_RESYNCED == PROPID_HEALTH_FLAGS_TIME_RESYNCED &&
                   PROPID_HEALTH_ROTOR_DAMAGE == PROPID_HEALTH_FLAGS_ROTOR_DAMAGE,
               "health bits mirror propid.h");

#define PROPID_MAVLINK_REJECTED_SLOTS 16u

static propid_mavlink_status_t check_sender(const propid_mavlink_sender_t *sender,
                                            const uint8_t *buf, const uint16_t *frame_len)
{
    if (sender == NULL || buf == NULL || frame_len == NULL) {
        return PROPID_MAVLINK_ERR_NULL;
    }
    if (sender->system_id == 0u) {
        return PROPID_MAVLINK_ERR_SYSTEM_ID;
    }
    return PROPID_MAVLINK_OK;
}

static void clear_len(uint16_t *frame_len)
{
    if (frame_len != NULL) {
        *frame_len = 0u;
    }
}

/* Our frames are never signed: header + trimmed payload + checksum. */
static uint16_t frame_size(const mavlink_message_t *msg)
{
    return (uint16_t)(MAVLINK_NUM_NON_PAYLOAD_BYTES + msg->len);
}

/* A link status that carries only the caller's sequence number (MAVLink 2, unsigned). */
/* Serialise `count` built messages into buf all or nothing (a ground station
 * must not see half a report); the sender's sequence advances only when written. */
static propid_mavlink_status_t write_frames(propid_mavlink_sender_t *sender, const mavlink_status_t *link,
                                            const mavlink_message_t *msgs, uint8_t count, uint8_t *buf,
                                            uint16_t buf_size, uint16_t *frame_len)
{
    uint32_t total = 0u;
    for (uint8_t i = 0u; i < count; ++i) {
        total += frame_size(&msgs[i]);
    }
    if (total > buf_size) {
        *frame_len = 0u;
        return PROPID_MAVLINK_ERR_BUFFER;
    }
    uint16_t used = 0u;
    for (uint8_t i = 0u; i < count; ++i) {
        used = (uint16_t)(used + mavlink_msg_to_send_buffer(buf + used, &msgs[i]));
    }
    sender->sequence = link->current_tx_seq;
    *frame_len = used;
    return PROPID_MAVLINK_OK;
}

static void link_from_sequence(uint8_t sequence, mavlink_status_t *link)
{
    const mavlink_status_t zero = {0};
    *link = zero;
    link->current_tx_seq = sequence;
}

/* FLU (filter) -> FRD (MAVLink): y and z change sign. */
static void flu_to_frd(const float flu[3], float frd[3])
{
    frd[0] = flu[0];
    frd[1] = -flu[1];
    frd[2] = -flu[2];
}

/* The builders finalise one message (already validated inputs); link->current_tx_seq
 * advances by one. */
static void build_coefficients(const propid_mavlink_sender_t *sender, mavlink_status_t *link,
                               const propid_estimate_t *estimate, mavlink_message_t *msg)
{
    float thrust[PROPID_MAVLINK_MAX_ROTORS] = {0.0f};
    float thrust_std[PROPID_MAVLINK_MAX_ROTORS] = {0.0f};
    float drag[PROPID_MAVLINK_MAX_ROTORS] = {0.0f};
    float drag_std[PROPID_MAVLINK_MAX_ROTORS] = {0.0f};
    for (uint8_t i = 0u; i < estimate->rotor_count; ++i) {
        thrust[i] = estimate->thrust_coeff[i];
        thrust_std[i] = estimate->thrust_coeff_std[i];
        drag[i] = estimate->drag_coeff[i];
        drag_std[i] = estimate->drag_coeff_std[i];
    }
    (void)mavlink_msg_propid_coefficients_pack_status(
        sender->system_id, sender->component_id, link, msg, estimate->time_us, thrust,
        thrust_std, drag, drag_std, estimate->thrust_coeff_converging,
        estimate->thrust_coeff_converged, estimate->drag_coeff_converging,
        estimate->drag_coeff_converged, estimate->rotor_count);
}

static void build_gyro(const propid_mavlink_sender_t *sender, mavlink_status_t *link,
                       const propid_estimate_t *estimate, mavlink_message_t *msg)
{
    float bias[3];
    float rate[3];
    float innovation[3];
    flu_to_frd(estimate->gyro_bias, bias);
    flu_to_frd(estimate->body_rate, rate);
    flu_to_frd(estimate->innovation, innovation);
    (void)mavlink_msg_propid_gyro_pack_status(
        sender->system_id, sender->component_id, link, msg, estimate->time_us, bias,
        estimate->gyro_bias_std, rate, estimate->body_rate_std, innovation,
        estimate->innovation_test_ratio, estimate->health);
}

static void build_status(const propid_mavlink_sender_t *sender, mavlink_status_t *link,
                         const propid_estimate_t *estimate, const propid_counters_t *counters,
                         mavlink_message_t *msg)
{
    uint32_t rejected[PROPID_MAVLINK_REJECTED_SLOTS] = {0u};
    uint32_t rejected_total = 0u;
    /* Slot 0 (status OK) is not a rejection; a wrapped total would lie, so saturate. */
    for (uint8_t reason = 1u; reason < PROPID_REJECT_SLOTS; ++reason) {
        const uint32_t count = counters->rejected[reason];
        rejected[reason] = count;
        rejected_total = (count > UINT32_MAX - rejected_total) ? UINT32_MAX : rejected_total + count;
    }
    (void)mavlink_msg_propid_status_pack_status(
        sender->system_id, sender->component_id, link, msg, estimate->time_us,
        estimate->health, counters->gyro_accepted, counters->rotor_accepted,
        counters->axis_gated, counters->gate_reopened, counters->cov_repairs,
        counters->state_clamps, counters->resyncs, rejected_total, rejected);
}

static void build_model(const propid_mavlink_sender_t *sender, mavlink_status_t *link,
                        const propid_estimate_t *estimate, const propid_counters_t *counters,
                        mavlink_message_t *msg)
{
    float torque[3];
    flu_to_frd(estimate->disturbance_torque, torque);
    /* The z bias and innovation: FLU z up -> FRD z down. */
    (void)mavlink_msg_propid_model_pack_status(
        sender->system_id, sender->component_id, link, msg, estimate->time_us, torque,
        estimate->disturbance_torque_std, -estimate->accel_bias, estimate->accel_bias_std,
        -estimate->accel_innovation, estimate->torque_scale, estimate->torque_scale_std,
        counters != NULL ? counters->accel_accepted : 0u, counters != NULL ? counters->accel_gated : 0u,
        counters != NULL ? counters->delay_overflows : 0u, estimate->rotor_delay_us,
        estimate->model_terms);
}

static propid_mavlink_status_t check_estimate(const propid_estimate_t *estimate)
{
    if (estimate == NULL) {
        return PROPID_MAVLINK_ERR_NULL;
    }
    if (estimate->rotor_count == 0u || estimate->rotor_count > PROPID_MAVLINK_MAX_ROTORS ||
        estimate->rotor_count > PROPID_MAX_ROTORS) {
        return PROPID_MAVLINK_ERR_ROTOR_COUNT;
    }
    return PROPID_MAVLINK_OK;
}

typedef enum { FRAME_COEFFICIENTS, FRAME_GYRO, FRAME_STATUS, FRAME_MODEL } frame_kind_t;

/* Shared body of the three single-frame packers. */
static propid_mavlink_status_t pack_one(frame_kind_t kind, propid_mavlink_sender_t *sender,
                                        const propid_estimate_t *estimate,
                                        const propid_counters_t *counters, uint8_t *buf,
                                        uint16_t buf_size, uint16_t *frame_len)
{
    propid_mavlink_status_t status = check_sender(sender, buf, frame_len);
    if (status == PROPID_MAVLINK_OK) {
        status = check_estimate(estimate);
    }
    if (status == PROPID_MAVLINK_OK && kind == FRAME_STATUS && counters == NULL) {
        status = PROPID_MAVLINK_ERR_NULL;
    }
    if (status != PROPID_MAVLINK_OK) {
        clear_len(frame_len);
        return status;
    }

    mavlink_status_t link;
    mavlink_message_t msg;
    link_from_sequence(sender->sequence, &link);
    if (kind == FRAME_COEFFICIENTS) {
        build_coefficients(sender, &link, estimate, &msg);
    } else if (kind == FRAME_GYRO) {
        build_gyro(sender, &link, estimate, &msg);
    } else if (kind == FRAME_MODEL) {
        build_model(sender, &link, estimate, counters, &msg);
    } else {
        build_status(sender, &link, estimate, counters, &msg);
    }
    return write_frames(sender, &link, &msg, 1u, buf, buf_size, frame_len);
}

propid_mavlink_status_t propid_mavlink_pack_coefficients(propid_mavlink_sender_t *sender,
                                                         const propid_estimate_t *estimate,
                                                         uint8_t *buf, uint16_t buf_size,
                                                         uint16_t *frame_len)
{
    return pack_one(FRAME_COEFFICIENTS, sender, estimate, NULL, buf, buf_size, frame_len);
}

propid_mavlink_status_t propid_mavlink_pack_gyro(propid_mavlink_sender_t *sender,
                                                 const propid_estimate_t *estimate,
                                                 uint8_t *buf, uint16_t buf_size,
                                                 uint16_t *frame_len)
{
    return pack_one(FRAME_GYRO, sender, estimate, NULL, buf, buf_size, frame_len);
}

propid_mavlink_status_t propid_mavlink_pack_status(propid_mavlink_sender_t *sender,
                                                   const propid_estimate_t *estimate,
                                                   const propid_counters_t *counters,
                                                   uint8_t *buf, uint16_t buf_size,
                                                   uint16_t *frame_len)
{
    return pack_one(FRAME_STATUS, sender, estimate, counters, buf, buf_size, frame_len);
}

propid_mavlink_status_t propid_mavlink_pack_model(propid_mavlink_sender_t *sender,
                                                  const propid_estimate_t *estimate,
                                                  const propid_counters_t *counters,
                                                  uint8_t *buf, uint16_t buf_size,
                                                  uint16_t *frame_len)
{
    return pack_one(FRAME_MODEL, sender, estimate, counters, buf, buf_size, frame_len);
}

propid_mavlink_status_t propid_mavlink_pack_report(propid_mavlink_sender_t *sender,
                                                   const propid_estimate_t *estimate,
                                                   const propid_counters_t *counters,
                                                   uint8_t *buf, uint16_t buf_size,
                                                   uint16_t *frame_len)
{
    propid_mavlink_status_t status = check_sender(sender, buf, frame_len);
    if (status == PROPID_MAVLINK_OK) {
        status = check_estimate(estimate);
    }
    if (status != PROPID_MAVLINK_OK) {
        clear_len(frame_len);
        return status;
    }

    /* Build every frame first (about 1200 bytes of stack), so that a report that does
     * not fit writes nothing at all. */
    mavlink_status_t link;
    mavlink_message_t msgs[4];
    uint8_t count = 0u;
    link_from_sequence(sender->sequence, &link);
    /* Coefficients last: receivers that assemble a row per PROPID_COEFFICIENTS then
     * already hold the status and gyro frames of the same instant. */
    if (counters != NULL) {
        build_status(sender, &link, estimate, counters, &msgs[count++]);
    }
    if (estimate->model_terms != 0u) {
        build_model(sender, &link, estimate, counters, &msgs[count++]);
    }
    build_gyro(sender, &link, estimate, &msgs[count++]);
    build_coefficients(sender, &link, estimate, &msgs[count++]);

    return write_frames(sender, &link, msgs, count, buf, buf_size, frame_len);
}

/* A detection the wire can carry: a rotor below the rotor count, at most 8 rotors. */
static propid_mavlink_status_t check_detection(const propid_damage_t *detector)
{
    if (detector == NULL) {
        return PROPID_MAVLINK_ERR_NULL;
    }
    if (detector->detections == 0u || detector->last_rotor < 0 || detector->rotor_count == 0u ||
        detector->rotor_count > PROPID_MAVLINK_MAX_ROTORS ||
        (uint8_t)detector->last_rotor >= detector->rotor_count) {
        return PROPID_MAVLINK_ERR_NO_DETECTION;
    }
    return PROPID_MAVLINK_OK;
}

static void build_damage(const propid_mavlink_sender_t *sender, mavlink_status_t *link,
                         const propid_damage_t *detector, mavlink_message_t *msg)
{
    (void)mavlink_msg_propid_damage_pack_status(
        sender->system_id, sender->component_id, link, msg, detector->last_detection_us,
        (uint8_t)((uint8_t)detector->last_rotor + 1u), detector->detections, detector->damaged_mask);
}

/* "propid: rotor N damaged, re-identifying" without printf (N is one digit). */
static void build_damage_text(const propid_mavlink_sender_t *sender, mavlink_status_t *link,
                              const propid_damage_t *detector, mavlink_message_t *msg)
{
    static const char head[] = "propid: rotor ";
    static const char tail[] = " damaged, re-identifying";
    char text[MAVLINK_MSG_STATUSTEXT_FIELD_TEXT_LEN] = {0};
    _Static_assert(sizeof(head) + sizeof(tail) <= sizeof(text), "damage text fits STATUSTEXT");
    size_t n = 0u;
    for (size_t i = 0u; i + 1u < sizeof(head); ++i) {
        text[n++] = head[i];
    }
    text[n++] = (char)('1' + detector->last_rotor);
    for (size_t i = 0u; i + 1u < sizeof(tail); ++i) {
        text[n++] = tail[i];
    }
    (void)mavlink_msg_statustext_pack_status(sender->system_id, sender->component_id, link, msg,
                                             MAV_SEVERITY_CRITICAL, text, 0u, 0u);
}

/* Shared body of the two damage packers: one or two frames, all or nothing. */
static propid_mavlink_status_t pack_damage(propid_mavlink_sender_t *sender,
                                           const propid_damage_t *detector, int with_text,
                                           uint8_t *buf, uint16_t buf_size, uint16_t *frame_len)
{
    propid_mavlink_status_t status = check_sender(sender, buf, frame_len);
    if (status == PROPID_MAVLINK_OK) {
        status = check_detection(detector);
    }
    if (status != PROPID_MAVLINK_OK) {
        clear_len(frame_len);
        return status;
    }
    mavlink_status_t link;
    mavlink_message_t msgs[2];
    uint8_t count = 0u;
    link_from_sequence(sender->sequence, &link);
    build_damage(sender, &link, detector, &msgs[count++]);
    if (with_text) {
        build_damage_text(sender, &link, detector, &msgs[count++]);
    }
    return write_frames(sender, &link, msgs, count, buf, buf_size, frame_len);
}

propid_mavlink_status_t propid_mavlink_pack_damage(propid_mavlink_sender_t *sender,
                                                   const propid_damage_t *detector,
                                                   uint8_t *buf, uint16_t buf_size,
                                                   uint16_t *frame_len)
{
    return pack_damage(sender, detector, 0, buf, buf_size, frame_len);
}

propid_mavlink_status_t propid_mavlink_pack_damage_alert(propid_mavlink_sender_t *sender,
                                                         const propid_damage_t *detector,
                                                         uint8_t *buf, uint16_t buf_size,
                                                         uint16_t *frame_len)
{
    return pack_damage(sender, detector, 1, buf, buf_size, frame_len);
}

uint8_t propid_mavlink_execute_reset(propid_filter_t *filter, float rotor_param)
{
    if (filter == NULL) {
        return PROPID_MAVLINK_RESULT_FAILED;
    }
    /* Exactly -1 means all rotors; anything else must be an integral index in range.
     * The comparisons are false for NaN, which is therefore denied. */
    if (rotor_param == -1.0f) {
        return (propid_reset(filter) == PROPID_OK) ? PROPID_MAVLINK_RESULT_ACCEPTED
                                                   : PROPID_MAVLINK_RESULT_FAILED;
    }
    if (!(rotor_param >= 0.0f && rotor_param < (float)PROPID_MAX_ROTORS)) {
        return PROPID_MAVLINK_RESULT_DENIED;
    }
    const uint8_t rotor = (uint8_t)rotor_param;
    if ((float)rotor != rotor_param) {
        return PROPID_MAVLINK_RESULT_DENIED;
    }
    const propid_status_t status = propid_reset_rotor(filter, rotor);
    if (status == PROPID_OK) {
        return PROPID_MAVLINK_RESULT_ACCEPTED;
    }
    return (status == PROPID_ERR_ROTOR_INDEX) ? PROPID_MAVLINK_RESULT_DENIED
                                              : PROPID_MAVLINK_RESULT_FAILED;
}

const char *propid_mavlink_status_name(propid_mavlink_status_t status)
{
    switch (status) {
    case PROPID_MAVLINK_OK:
        return "PROPID_MAVLINK_OK";
    case PROPID_MAVLINK_ERR_NULL:
        return "PROPID_MAVLINK_ERR_NULL";
    case PROPID_MAVLINK_ERR_BUFFER:
        return "PROPID_MAVLINK_ERR_BUFFER";
    case PROPID_MAVLINK_ERR_ROTOR_COUNT:
        return "PROPID_MAVLINK_ERR_ROTOR_COUNT";
    case PROPID_MAVLINK_ERR_SYSTEM_ID:
        return "PROPID_MAVLINK_ERR_SYSTEM_ID";
    case PROPID_MAVLINK_ERR_NO_DETECTION:
        return "PROPID_MAVLINK_ERR_NO_DETECTION";
    default:
        return "PROPID_MAVLINK_UNKNOWN";
    }
}
