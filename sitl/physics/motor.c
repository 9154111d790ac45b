/* First-order motor model (see motor.h). */
#include "motor.h"

#include <math.h>

double sitl_motor_clamp(const sitl_motor_t *motor, double speed)
{
    if (!(speed >= motor->speed_min)) { /* also catches NaN */
        return motor->speed_min;
    }
    if (speed > motor->speed_max) {
        return motor->speed_max;
    }
    return speed;
}

double sitl_motor_acceleration(const sitl_motor_t *motor, double command, double speed)
{
    return (sitl_motor_clamp(motor, command) - speed) / motor->time_constant;
}
