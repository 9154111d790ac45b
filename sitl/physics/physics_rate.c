/* The physics step's accuracy rule (see physics_rate.h). */
#include "physics_rate.h"

#include <math.h>

double sitl_physics_rate_for(double motor_time_constant_s, double control_rate_hz)
{
    if (!(motor_time_constant_s > 0.0) || !isfinite(motor_time_constant_s) ||
        !(control_rate_hz > 0.0) || !isfinite(control_rate_hz)) {
        return 0.0;
    }
    const double motor_rate = 1.0 / (SITL_PHYSICS_STEP_PER_TIME_CONSTANT * motor_time_constant_s);
    const double attitude_rate = SITL_PHYSICS_FASTEST_BODY_RATE / SITL_PHYSICS_STEP_PER_TIME_CONSTANT;
    const double needed = fmax(motor_rate, attitude_rate);
    /* A relative tolerance so that a rate the bound meets exactly (tau_m 5 ms at 500 Hz
     * control: 2000 Hz) is not pushed one multiple up by the rounding of the division. */
    double multiple = ceil(needed / control_rate_hz * (1.0 - 1e-12));
    if (multiple < 1.0) {
        multiple = 1.0;
    }
    return multiple * control_rate_hz;
}
