/*
 * Minimal bare-metal integration of propid in a flight controller's loop.
 *
 * The board's drivers call the two callbacks from interrupt context:
 *   port_on_esc_telemetry()  ESC telemetry frame (eRPM of every motor)
 *   port_on_gyro_sample()    gyro data-ready interrupt
 * and the main loop calls port_loop_step() as often as it can: it feeds the
 * filter, runs a rate controller and the allocation, and returns rotor-speed
 * commands for the ESCs. See docs/integration.md for PX4, ArduPilot, Betaflight.
 */
#ifndef PROPID_PORT_EXAMPLE_H
#define PROPID_PORT_EXAMPLE_H

#include <stdint.h>

#include "port_allocation.h"
#include "propid/propid.h"

/* Vehicle description the example flies (Hummingbird-class plus-frame quad). */
#define PORT_MOTOR_POLE_PAIRS 7u
#define PORT_MAX_ROTOR_SPEED 1500.0f     /* rad/s */
#define PORT_GYRO_RATE_HZ 1000.0f
#define PORT_ALLOCATION_PERIOD_US 50000u /* re-read the estimate at 20 Hz */

void port_vehicle_config(propid_config_t *config);

propid_status_t port_init(void);

/* ISR context: they only convert units and queue; the filter runs in the loop. */
void port_on_esc_telemetry(uint64_t time_us, const uint32_t erpm[PORT_ROTORS]);
void port_on_gyro_sample(uint64_t time_us, const float gyro_rad_s[3]);

/* Setpoint of the rate loop: body rates [rad/s] and collective thrust [N]. */
void port_set_setpoint(const float body_rate[3], float thrust_n);

/* Main loop: returns 1 and writes rotor-speed commands [rad/s] when a gyro
 * sample was processed, 0 when there was nothing to do. */
int port_loop_step(float rotor_speed_cmd[PORT_ROTORS]);

/* For the board's report. */
const propid_config_t *port_vehicle(void);
const propid_filter_t *port_filter(void);
const port_allocation_t *port_allocation(void);
uint32_t port_dropped_samples(void);
uint32_t port_rejected_samples(void);

#endif /* PROPID_PORT_EXAMPLE_H */
