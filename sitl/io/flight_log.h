/*
 * Flight log v1 CSV writer for the SITL (docs/flightlog.md): the v1 columns
 * (t, gyro_*, omega_i, acc_*, q*, v*, p*, cmd_i) plus reference, truth and
 * filter columns, then true_omega_i (extra, for gap diagnosis). A missing
 * value (no sample yet) is an empty field. Numbers are printed with %.9g so
 * the same run gives the same bytes.
 */
#ifndef SITL_FLIGHT_LOG_H
#define SITL_FLIGHT_LOG_H

#include <stdio.h>

#include "propid/propid.h"
#include "vehicle.h"

typedef struct {
    double t;
    double gyro[3];                       /* latest gyro sample (bias included) */
    double omega[SITL_MAX_ROTORS];        /* latest ESC telemetry received */
    double acc[3];                        /* latest accelerometer sample */
    double quat[4];
    double velocity[3];
    double position[3];
    double cmd[SITL_MAX_ROTORS];          /* speed command / rotor_speed_max, 0..1 */
    double ref_position[3];
    double ref_yaw;
    double true_kf[SITL_MAX_ROTORS];
    double true_km[SITL_MAX_ROTORS];
    double true_bias[3];
    double true_rate[3];
    double true_omega[SITL_MAX_ROTORS];
    propid_estimate_t estimate;
    int status;                           /* status of the latest propid_push_gyro */
} sitl_log_row_t;

typedef struct {
    FILE *file;
    int rotor_count;
} sitl_flight_log_t;

/* Create the CSV and write the header. Returns 0, or -1 (errno set). */
int sitl_flight_log_open(sitl_flight_log_t *log, const char *path, int rotor_count);
int sitl_flight_log_write(sitl_flight_log_t *log, const sitl_log_row_t *row);
/* Returns 0, or -1 if anything failed to reach the disk. */
int sitl_flight_log_close(sitl_flight_log_t *log);

/* "X.csv" -> "X.vehicle.json" (any other name: name + ".vehicle.json"). */
void sitl_flight_log_vehicle_path(const char *csv_path, char *out, size_t out_size);

#endif /* SITL_FLIGHT_LOG_H */
