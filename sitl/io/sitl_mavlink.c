/*
 * SITL <-> ground station MAVLink 2 link over UDP (see sitl_mavlink.h).
 *
 * One non-blocking, unconnected UDP socket: frames go to the configured
 * HOST:PORT whether or not anyone listens (send errors are counted, never
 * fatal), and commands are read from the same socket. The propid dialect
 * frames come from the firmware's report packer (propid_mavlink), so the
 * simulator exercises exactly the code an autopilot would run; the standard
 * messages let MAVProxy, QGroundControl and mavlogdump show the vehicle
 * without our dialect. The simulator works in world ENU / body FLU; MAVLink
 * wants NED / FRD: every conversion happens in this file.
 */
#define _POSIX_C_SOURCE 200809L

#include "sitl_mavlink.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netdb.h>
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/types.h>
#include <unistd.h>

#include "propid/propid_mavlink.h"

#define MAVLINK_NO_CONVERSION_HELPERS
#include "mavlink/propid/mavlink.h"

/* Our dialect re-declares the standard ESC_STATUS; it must keep the standard wire format. */
_Static_assert(MAVLINK_MSG_ID_ESC_STATUS == 291 && MAVLINK_MSG_ID_ESC_STATUS_CRC == 10,
               "ESC_STATUS must match the standard message");

#define SITL_MAVLINK_SYSTEM_ID 1u
#define SITL_MAVLINK_COMPONENT_ID MAV_COMP_ID_AUTOPILOT1
#define SITL_MAVLINK_MAX_HOST 256
/* Bound on datagrams read per poll, so a flood cannot stall the simulation. */
#define SITL_MAVLINK_MAX_READS_PER_POLL 64
#define SITL_MAVLINK_PI 3.14159265358979323846

typedef struct {
    double period_s; /* <= 0: never */
    double next_s;   /* simulation time the message is next due */
} schedule_t;

struct sitl_mavlink {
    int socket_fd;
    struct sockaddr_storage dest;
    socklen_t dest_len;
    schedule_t heartbeat, attitude, imu, esc, estimate, status;
    propid_mavlink_sender_t sender; /* ids + the one sequence number of every frame */
    mavlink_status_t rx_status;
    mavlink_message_t rx_msg;   /* frame being assembled by the parser */
    unsigned long frames_sent;
    unsigned long frames_dropped;
};

void sitl_mavlink_default_rates(sitl_mavlink_rates_t *rates)
{
    if (rates == NULL) {
        return;
    }
    rates->heartbeat_hz = 1.0;
    rates->attitude_hz = 50.0;
    rates->imu_hz = 50.0;
    rates->esc_hz = 20.0;
    rates->estimate_hz = 20.0;
    rates->status_hz = 2.0;
}

static void schedule_init(schedule_t *schedule, double rate_hz)
{
    schedule->period_s = (rate_hz > 0.0 && isfinite(rate_hz)) ? 1.0 / rate_hz : 0.0;
    schedule->next_s = -INFINITY; /* the first update sends everything once */
}

/* True when the message is due at time_s; then plans the next one. After a time
 * jump (or a slow caller) it re-anchors instead of sending a burst of catch-ups. */
static int schedule_due(schedule_t *schedule, double time_s)
{
    if (schedule->period_s <= 0.0 || time_s < schedule->next_s) {
        return 0;
    }
    schedule->next_s += schedule->period_s;
    if (schedule->next_s <= time_s) {
        schedule->next_s = time_s + schedule->period_s;
    }
    return 1;
}

/* "udp:HOST:PORT" -> socket address. Prints why and returns -1 on a bad url. */
static int parse_url(const char *url, struct sockaddr_storage *addr, socklen_t *addr_len)
{
    static const char prefix[] = "udp:";
    if (url == NULL || strncmp(url, prefix, sizeof prefix - 1u) != 0) {
        fprintf(stderr, "sitl_mavlink: url '%s' is not udp:HOST:PORT\n", url ? url : "(null)");
        return -1;
    }
    const char *host_start = url + sizeof prefix - 1u;
    const char *colon = strrchr(host_start, ':');
    if (colon == NULL || colon == host_start) {
        fprintf(stderr, "sitl_mavlink: url '%s' is not udp:HOST:PORT\n", url);
        return -1;
    }
    size_t host_len = (size_t)(colon - host_start);
    if (host_len >= SITL_MAVLINK_MAX_HOST) {
        fprintf(stderr, "sitl_mavlink: host name too long in '%s'\n", url);
        return -1;
    }
    char host[SITL_MAVLINK_MAX_HOST];
    memcpy(host, host_start, host_len);
    host[host_len] = '\0';

    char *end = NULL;
    errno = 0;
    const long port = strtol(colon + 1, &end, 10);
    if (errno != 0 || end == colon + 1 || *end != '\0' || port < 1 || port > 65535) {
        fprintf(stderr, "sitl_mavlink: bad port in '%s' (1..65535)\n", url);
        return -1;
    }

    struct addrinfo hints;
    memset(&hints, 0, sizeof hints);
    hints.ai_family = AF_INET;
    hints.ai_socktype = SOCK_DGRAM;
    struct addrinfo *found = NULL;
    const int rc = getaddrinfo(host, colon + 1, &hints, &found);
    if (rc != 0 || found == NULL) {
        fprintf(stderr, "sitl_mavlink: cannot resolve '%s': %s\n", host, gai_strerror(rc));
        return -1;
    }
    memcpy(addr, found->ai_addr, found->ai_addrlen);
    *addr_len = (socklen_t)found->ai_addrlen;
    freeaddrinfo(found);
    return 0;
}

sitl_mavlink_t *sitl_mavlink_open(const char *url, const sitl_mavlink_rates_t *rates)
{
    sitl_mavlink_rates_t defaults;
    sitl_mavlink_default_rates(&defaults);
    if (rates == NULL) {
        rates = &defaults;
    }

    struct sockaddr_storage dest;
    socklen_t dest_len = 0;
    if (parse_url(url, &dest, &dest_len) != 0) {
        return NULL;
    }
    const int fd = socket(AF_INET, SOCK_DGRAM, 0);
    if (fd < 0) {
        fprintf(stderr, "sitl_mavlink: socket: %s\n", strerror(errno));
        return NULL;
    }
    const int flags = fcntl(fd, F_GETFL, 0);
    if (flags < 0 || fcntl(fd, F_SETFL, flags | O_NONBLOCK) < 0) {
        fprintf(stderr, "sitl_mavlink: cannot make the socket non-blocking: %s\n", strerror(errno));
        close(fd);
        return NULL;
    }
    /* Bind to an ephemeral port now so replies can reach us before the first send. */
    struct sockaddr_in local;
    memset(&local, 0, sizeof local);
    local.sin_family = AF_INET;
    local.sin_addr.s_addr = htonl(INADDR_ANY);
    local.sin_port = 0;
    if (bind(fd, (const struct sockaddr *)&local, sizeof local) != 0) {
        fprintf(stderr, "sitl_mavlink: bind: %s\n", strerror(errno));
        close(fd);
        return NULL;
    }

    sitl_mavlink_t *link = calloc(1u, sizeof *link);
    if (link == NULL) {
        fprintf(stderr, "sitl_mavlink: out of memory\n");
        close(fd);
        return NULL;
    }
    link->socket_fd = fd;
    link->dest = dest;
    link->dest_len = dest_len;
    schedule_init(&link->heartbeat, rates->heartbeat_hz);
    schedule_init(&link->attitude, rates->attitude_hz);
    schedule_init(&link->imu, rates->imu_hz);
    schedule_init(&link->esc, rates->esc_hz);
    schedule_init(&link->estimate, rates->estimate_hz);
    schedule_init(&link->status, rates->status_hz);
    link->sender.system_id = SITL_MAVLINK_SYSTEM_ID;
    link->sender.component_id = SITL_MAVLINK_COMPONENT_ID;
    link->sender.sequence = 0u;
    return link;
}

void sitl_mavlink_close(sitl_mavlink_t *link)
{
    if (link == NULL) {
        return;
    }
    if (link->frames_dropped > 0u) {
        fprintf(stderr, "sitl_mavlink: %lu of %lu frames could not be sent\n",
                link->frames_dropped, link->frames_sent + link->frames_dropped);
    }
    close(link->socket_fd);
    free(link);
}

/* One datagram per frame. Nobody listening (ECONNREFUSED from an earlier ICMP),
 * a full socket buffer or a vanished route only drop this frame. */
static void send_bytes(sitl_mavlink_t *link, const uint8_t *bytes, uint16_t len,
                       const struct sockaddr *to, socklen_t to_len)
{
    const ssize_t sent = sendto(link->socket_fd, bytes, len, 0, to, to_len);
    if (sent == (ssize_t)len) {
        link->frames_sent++;
    } else {
        link->frames_dropped++;
    }
}

/* Finalise a message packed with our sequence number and send it to the ground station. */
static void send_message(sitl_mavlink_t *link, const mavlink_message_t *msg)
{
    uint8_t buf[MAVLINK_MAX_PACKET_LEN];
    const uint16_t len = mavlink_msg_to_send_buffer(buf, msg);
    send_bytes(link, buf, len, (const struct sockaddr *)&link->dest, link->dest_len);
}

/* A link status carrying only our sequence number; after packing, take it back. */
static mavlink_status_t tx_status(const sitl_mavlink_t *link)
{
    mavlink_status_t status;
    memset(&status, 0, sizeof status);
    status.current_tx_seq = link->sender.sequence;
    return status;
}

static uint32_t time_boot_ms(double time_s)
{
    return (time_s > 0.0) ? (uint32_t)(time_s * 1000.0) : 0u;
}

static uint64_t time_usec(double time_s)
{
    return (time_s > 0.0) ? (uint64_t)llround(time_s * 1e6) : 0u;
}

/* The airframe a ground station draws (its icon, its motor test page): by rotor count. */
static uint8_t vehicle_type(int rotor_count)
{
    switch (rotor_count) {
    case 3:
        return MAV_TYPE_TRICOPTER;
    case 4:
        return MAV_TYPE_QUADROTOR;
    case 6:
        return MAV_TYPE_HEXAROTOR;
    case 8:
        return MAV_TYPE_OCTOROTOR;
    default:
        return MAV_TYPE_GENERIC_MULTIROTOR;
    }
}

static void send_heartbeat(sitl_mavlink_t *link, int rotor_count)
{
    mavlink_status_t status = tx_status(link);
    mavlink_message_t msg;
    mavlink_msg_heartbeat_pack_status(link->sender.system_id, link->sender.component_id, &status,
                                      &msg, vehicle_type(rotor_count), MAV_AUTOPILOT_GENERIC,
                                      MAV_MODE_FLAG_SAFETY_ARMED | MAV_MODE_FLAG_AUTO_ENABLED |
                                          MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                      0u, MAV_STATE_ACTIVE);
    link->sender.sequence = status.current_tx_seq;
    send_message(link, &msg);
}

/* Body FLU -> FRD and world ENU -> NED. */
static void flu_to_frd(const double flu[3], float frd[3])
{
    frd[0] = (float)flu[0];
    frd[1] = (float)-flu[1];
    frd[2] = (float)-flu[2];
}

static void enu_to_ned(const double enu[3], float ned[3])
{
    ned[0] = (float)enu[1];
    ned[1] = (float)enu[0];
    ned[2] = (float)-enu[2];
}

/* Roll, pitch, yaw (ZYX, MAVLink convention) of body FRD in world NED, from the
 * body FLU -> world ENU quaternion: R_ned_frd = T * R_enu_flu * D with T swapping
 * x/y and negating z, D = diag(1, -1, -1). */
static void attitude_ned_frd(const double q[4], double *roll, double *pitch, double *yaw)
{
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    const double n = sqrt(w * w + x * x + y * y + z * z);
    const double qw = w / n, qx = x / n, qy = y / n, qz = z / n;
    double r_enu[3][3] = {
        {1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - qw * qz), 2.0 * (qx * qz + qw * qy)},
        {2.0 * (qx * qy + qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz - qw * qx)},
        {2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy)},
    };
    static const int row_from[3] = {1, 0, 2};            /* T: north = ENU y, east = ENU x */
    static const double row_sign[3] = {1.0, 1.0, -1.0};   /* T: down = -ENU z */
    static const double col_sign[3] = {1.0, -1.0, -1.0}; /* D */
    double r[3][3];
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
            r[i][j] = row_sign[i] * r_enu[row_from[i]][j] * col_sign[j];
        }
    }
    *roll = atan2(r[2][1], r[2][2]);
    const double s = -r[2][0];
    *pitch = asin(s > 1.0 ? 1.0 : (s < -1.0 ? -1.0 : s));
    *yaw = atan2(r[1][0], r[0][0]);
}

void sitl_mavlink_damage(sitl_mavlink_t *link, const propid_damage_t *detector)
{
    if (link == NULL) {
        return;
    }
    /* The firmware's own packer: PROPID_DAMAGE, then the CRITICAL STATUSTEXT. */
    uint8_t buf[PROPID_MAVLINK_DAMAGE_ALERT_MAX_LEN];
    uint16_t len = 0u;
    if (propid_mavlink_pack_damage_alert(&link->sender, detector, buf, sizeof buf, &len) ==
        PROPID_MAVLINK_OK) {
        send_bytes(link, buf, len, (const struct sockaddr *)&link->dest, link->dest_len);
    }
}

static void send_attitude_and_position(sitl_mavlink_t *link, const sitl_mavlink_snapshot_t *snap)
{
    double roll, pitch, yaw;
    attitude_ned_frd(snap->quat_wxyz, &roll, &pitch, &yaw);
    float rate[3];
    flu_to_frd(snap->gyro_rad_s, rate);

    mavlink_status_t status = tx_status(link);
    mavlink_message_t msg;
    mavlink_msg_attitude_pack_status(link->sender.system_id, link->sender.component_id, &status,
                                     &msg, time_boot_ms(snap->time_s), (float)roll, (float)pitch,
                                     (float)yaw, rate[0], rate[1], rate[2]);
    link->sender.sequence = status.current_tx_seq;
    send_message(link, &msg);

    float pos[3], vel[3];
    enu_to_ned(snap->position_m, pos);
    enu_to_ned(snap->velocity_m_s, vel);
    status = tx_status(link);
    mavlink_msg_local_position_ned_pack_status(link->sender.system_id, link->sender.component_id,
                                               &status, &msg, time_boot_ms(snap->time_s), pos[0],
                                               pos[1], pos[2], vel[0], vel[1], vel[2]);
    link->sender.sequence = status.current_tx_seq;
    send_message(link, &msg);
}

static void send_imu(sitl_mavlink_t *link, const sitl_mavlink_snapshot_t *snap)
{
    float acc[3], gyro[3];
    flu_to_frd(snap->accel_m_s2, acc);
    flu_to_frd(snap->gyro_rad_s, gyro);
    /* Bits 0-5 of fields_updated: x/y/z acceleration and x/y/z gyro. */
    const uint16_t fields_updated = 0x3Fu;
    mavlink_status_t status = tx_status(link);
    mavlink_message_t msg;
    mavlink_msg_highres_imu_pack_status(link->sender.system_id, link->sender.component_id, &status,
                                        &msg, time_usec(snap->time_s), acc[0], acc[1], acc[2],
                                        gyro[0], gyro[1], gyro[2], 0.0f, 0.0f, 0.0f, 0.0f, 0.0f,
                                        0.0f, 0.0f, fields_updated, 0u);
    link->sender.sequence = status.current_tx_seq;
    send_message(link, &msg);
}

/* ESC_STATUS carries 4 ESCs; more rotors take more messages (index = first ESC). */
static void send_esc(sitl_mavlink_t *link, const sitl_mavlink_snapshot_t *snap)
{
    const double rad_s_to_rpm = 60.0 / (2.0 * SITL_MAVLINK_PI);
    int count = snap->rotor_count;
    if (count > PROPID_MAX_ROTORS) {
        count = PROPID_MAX_ROTORS;
    }
    for (int first = 0; first < count; first += 4) {
        int32_t rpm[4] = {0, 0, 0, 0};
        float voltage[4] = {0.0f, 0.0f, 0.0f, 0.0f};
        float current[4] = {0.0f, 0.0f, 0.0f, 0.0f};
        for (int i = 0; i < 4 && first + i < count; ++i) {
            rpm[i] = (int32_t)lround(snap->rotor_speed_rad_s[first + i] * rad_s_to_rpm);
        }
        mavlink_status_t status = tx_status(link);
        mavlink_message_t msg;
        mavlink_msg_esc_status_pack_status(link->sender.system_id, link->sender.component_id,
                                           &status, &msg, (uint8_t)first, time_usec(snap->time_s),
                                           rpm, voltage, current);
        link->sender.sequence = status.current_tx_seq;
        send_message(link, &msg);
    }
}

/* The dialect frames come from the firmware packer: what flies is what is tested. */
static void send_estimate(sitl_mavlink_t *link, const propid_filter_t *filter, int estimate_due,
                          int status_due)
{
    propid_estimate_t estimate;
    propid_counters_t counters;
    if (propid_get_estimate(filter, &estimate) != PROPID_OK ||
        propid_get_counters(filter, &counters) != PROPID_OK) {
        return;
    }
    uint8_t buf[PROPID_MAVLINK_REPORT_MAX_LEN];
    uint16_t len = 0u;
    /* Status and gyro before the coefficients: a receiver that completes a row on
     * PROPID_COEFFICIENTS (propid log) then has the gyro side of the same instant. */
    if (status_due) {
        if (propid_mavlink_pack_status(&link->sender, &estimate, &counters, buf, sizeof buf,
                                       &len) == PROPID_MAVLINK_OK) {
            send_bytes(link, buf, len, (const struct sockaddr *)&link->dest, link->dest_len);
        }
    }
    if (estimate_due) {
        if (estimate.model_terms != 0u &&
            propid_mavlink_pack_model(&link->sender, &estimate, &counters, buf, sizeof buf, &len) ==
                PROPID_MAVLINK_OK) {
            send_bytes(link, buf, len, (const struct sockaddr *)&link->dest, link->dest_len);
        }
        if (propid_mavlink_pack_gyro(&link->sender, &estimate, buf, sizeof buf, &len) ==
            PROPID_MAVLINK_OK) {
            send_bytes(link, buf, len, (const struct sockaddr *)&link->dest, link->dest_len);
        }
        if (propid_mavlink_pack_coefficients(&link->sender, &estimate, buf, sizeof buf, &len) ==
            PROPID_MAVLINK_OK) {
            send_bytes(link, buf, len, (const struct sockaddr *)&link->dest, link->dest_len);
        }
    }
}

void sitl_mavlink_update(sitl_mavlink_t *link, const sitl_mavlink_snapshot_t *snapshot,
                         const propid_filter_t *filter)
{
    if (link == NULL || snapshot == NULL || !isfinite(snapshot->time_s)) {
        return;
    }
    const double t = snapshot->time_s;
    if (schedule_due(&link->heartbeat, t)) {
        send_heartbeat(link, snapshot->rotor_count);
    }
    if (schedule_due(&link->attitude, t)) {
        send_attitude_and_position(link, snapshot);
    }
    if (schedule_due(&link->imu, t)) {
        send_imu(link, snapshot);
    }
    if (schedule_due(&link->esc, t)) {
        send_esc(link, snapshot);
    }
    const int estimate_due = schedule_due(&link->estimate, t);
    const int status_due = schedule_due(&link->status, t);
    if (filter != NULL && (estimate_due || status_due)) {
        send_estimate(link, filter, estimate_due, status_due);
    }
}

static void send_command_ack(sitl_mavlink_t *link, const mavlink_command_long_t *command,
                             const mavlink_message_t *request, uint8_t result,
                             const struct sockaddr *to, socklen_t to_len)
{
    mavlink_status_t status = tx_status(link);
    mavlink_message_t msg;
    mavlink_msg_command_ack_pack_status(link->sender.system_id, link->sender.component_id, &status,
                                        &msg, command->command, result, 0u, 0, request->sysid,
                                        request->compid);
    link->sender.sequence = status.current_tx_seq;
    uint8_t buf[MAVLINK_MAX_PACKET_LEN];
    const uint16_t len = mavlink_msg_to_send_buffer(buf, &msg);
    send_bytes(link, buf, len, to, to_len);
}

/* Execute one COMMAND_LONG addressed to us; returns 1 when a reset was executed. */
static int handle_command(sitl_mavlink_t *link, propid_filter_t *filter,
                          const mavlink_message_t *msg, const struct sockaddr *from,
                          socklen_t from_len)
{
    mavlink_command_long_t command;
    mavlink_msg_command_long_decode(msg, &command);
    const int for_us = (command.target_system == 0u ||
                        command.target_system == link->sender.system_id) &&
                       (command.target_component == 0u ||
                        command.target_component == link->sender.component_id);
    if (!for_us) {
        return 0;
    }
    if (command.command != MAV_CMD_PROPID_RESET) {
        send_command_ack(link, &command, msg, MAV_RESULT_UNSUPPORTED, from, from_len);
        return 0;
    }
    /* propid_mavlink_execute_reset answers FAILED for a NULL filter. */
    const uint8_t result = propid_mavlink_execute_reset(filter, command.param1);
    send_command_ack(link, &command, msg, result, from, from_len);
    if (result == MAV_RESULT_ACCEPTED) {
        fprintf(stderr, "sitl_mavlink: MAV_CMD_PROPID_RESET param1=%g executed\n",
                (double)command.param1);
        return 1;
    }
    return 0;
}

int sitl_mavlink_poll(sitl_mavlink_t *link, propid_filter_t *filter)
{
    if (link == NULL) {
        return 0;
    }
    int executed = 0;
    for (int reads = 0; reads < SITL_MAVLINK_MAX_READS_PER_POLL; ++reads) {
        uint8_t datagram[2048];
        struct sockaddr_storage from;
        socklen_t from_len = sizeof from;
        const ssize_t got = recvfrom(link->socket_fd, datagram, sizeof datagram, 0,
                                     (struct sockaddr *)&from, &from_len);
        if (got < 0) {
            /* EAGAIN: nothing more. ECONNREFUSED: an ICMP error from an earlier send
             * to a port nobody listens on; consume it and keep reading. */
            if (errno == ECONNREFUSED || errno == EINTR) {
                continue;
            }
            break;
        }
        for (ssize_t i = 0; i < got; ++i) {
            mavlink_message_t msg;
            mavlink_status_t msg_status;
            if (mavlink_frame_char_buffer(&link->rx_msg, &link->rx_status, datagram[i], &msg,
                                          &msg_status) != MAVLINK_FRAMING_OK) {
                continue;
            }
            if (msg.msgid == MAVLINK_MSG_ID_COMMAND_LONG) {
                executed += handle_command(link, filter, &msg, (const struct sockaddr *)&from,
                                           from_len);
            }
        }
    }
    return executed;
}
