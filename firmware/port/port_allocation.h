/*
 * Control allocation of a quadrotor from the propid estimate: maps the wanted
 * collective thrust and body torques to rotor speeds, with each rotor's kf and
 * km taken from the filter once they have converged and from the nominal
 * configuration until then.
 */
#ifndef PROPID_PORT_ALLOCATION_H
#define PROPID_PORT_ALLOCATION_H

#include <stdint.h>

#include "propid/propid.h"

#define PORT_ROTORS 4u

typedef struct {
    /* rotor_speed_sq = speed_sq_per_wrench * [thrust, tau_x, tau_y, tau_z] */
    float speed_sq_per_wrench[PORT_ROTORS][4];
    float thrust_coeff[PORT_ROTORS];   /* kf used to build it [N/(rad/s)^2] */
    float drag_coeff[PORT_ROTORS];     /* km used to build it [N m/(rad/s)^2] */
    uint16_t estimated_thrust_mask;    /* bit i: rotor i's kf came from the filter */
    uint16_t estimated_drag_mask;
} port_allocation_t;

/* Build from the configuration and (may be NULL) an estimate. Returns 0 on
 * success, -1 if the effectiveness matrix is singular (then *allocation is untouched). */
int port_allocation_build(port_allocation_t *allocation, const propid_config_t *config,
                          const propid_estimate_t *estimate);

/* wrench = [collective thrust N, tau_x, tau_y, tau_z N m] (body FLU). Rotor speeds
 * are clipped to [0, max_rotor_speed]. */
void port_allocation_apply(const port_allocation_t *allocation, const float wrench[4],
                           float max_rotor_speed, float rotor_speed[PORT_ROTORS]);

#endif /* PROPID_PORT_ALLOCATION_H */
