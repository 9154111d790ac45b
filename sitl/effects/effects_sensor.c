/* Sensor-side effects: gyro_scale and esc_delay (see effects.h, docs/sitl.md). */
#include "effects.h"

void sitl_effects_gyro_matrix(const sitl_effects_t *effects, double m[3][3])
{
    double s = sitl_effect_strength(effects, SITL_EFFECT_GYRO_SCALE);
    /* Scale errors of different sign per axis plus a small non-orthogonal
     * mounting (x/y cross-coupling, z tilted towards x): a generic MEMS part
     * on a slightly crooked board. s = 0 gives the identity. */
    m[0][0] = 1.0 + s;
    m[0][1] = 0.5 * s;
    m[0][2] = 0.0;
    m[1][0] = 0.5 * s;
    m[1][1] = 1.0 - s;
    m[1][2] = 0.0;
    m[2][0] = -0.5 * s;
    m[2][1] = 0.0;
    m[2][2] = 1.0 + 0.5 * s;
}

double sitl_effects_esc_extra_delay(const sitl_effects_t *effects)
{
    double d = sitl_effect_strength(effects, SITL_EFFECT_ESC_DELAY);
    return d > 0.0 ? d : 0.0;
}
