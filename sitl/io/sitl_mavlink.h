/*
 * SITL <-> ground station link: MAVLink 2 over UDP (our propid dialect plus
 * standard messages). The simulator calls sitl_mavlink_update() every control
 * step; the link decides from its configured rates what is due and sends it,
 * whether or not anyone listens. Frames are FLU/ENU inside; this file converts
 * to MAVLink's FRD/NED at the edge.
 */
#ifndef SITL_MAVLINK_H
#define SITL_MAVLINK_H

#include <stdint.h>

#include "propid/propid.h"
#include "propid/propid_damage.h"

typedef struct {
    double heartbeat_hz;     /* HEARTBEAT, default 1 */
    double attitude_hz;      /* ATTITUDE + LOCAL_POSITION_NED, default 50 */
    double imu_hz;           /* HIGHRES_IMU, default 50 */
    double esc_hz;           /* ESC_STATUS, default 20 */
    double estimate_hz;      /* propid dialect estimate messages, default 20 */
    double status_hz;        /* propid dialect health/counters, default 2 */
} sitl_mavlink_rates_t;

/* What the link reports; world ENU, body FLU, SI units. */
typedef struct {
    double time_s;
    double quat_wxyz[4];           /* body -> world */
    double position_m[3];
    double velocity_m_s[3];
    double gyro_rad_s[3];          /* as measured (bias included) */
    double accel_m_s2[3];          /* specific force, body */
    double rotor_speed_rad_s[PROPID_MAX_ROTORS];
    int rotor_count;
} sitl_mavlink_snapshot_t;

typedef struct sitl_mavlink sitl_mavlink_t;

void sitl_mavlink_default_rates(sitl_mavlink_rates_t *rates);

/* url: "udp:HOST:PORT" (send to HOST:PORT, listen for replies on the same socket).
 * Returns NULL (and prints why to stderr) on a bad url or socket error. */
sitl_mavlink_t *sitl_mavlink_open(const char *url, const sitl_mavlink_rates_t *rates);
void sitl_mavlink_close(sitl_mavlink_t *link);

/* Send whatever is due at snapshot->time_s. filter may be NULL (no estimator). */
void sitl_mavlink_update(sitl_mavlink_t *link, const sitl_mavlink_snapshot_t *snapshot,
                         const propid_filter_t *filter);

/* The detector's latest detection: PROPID_DAMAGE and a STATUSTEXT (CRITICAL) a
 * ground station shows, packed by the firmware's propid_mavlink_pack_damage_alert. */
void sitl_mavlink_damage(sitl_mavlink_t *link, const propid_damage_t *detector);

/* Read pending incoming frames without blocking; a COMMAND_LONG asking for a
 * filter reset (all rotors or one) is executed on filter and acknowledged with
 * COMMAND_ACK. Returns the number of commands executed. */
int sitl_mavlink_poll(sitl_mavlink_t *link, propid_filter_t *filter);

#endif /* SITL_MAVLINK_H */
