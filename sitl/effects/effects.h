/*
 * Switchable unmodelled effects (the effect ids shared with `propid gap`). All are OFF by default,
 * which gives the paper's conditions (the filter's model is then exact up to
 * sensor imperfections). Each has a strength; 1 means "the documented typical
 * value" for multiplicative effects, or is the physical quantity itself (see
 * sitl_effect_info_t.meaning). Formulas, defaults and sources: docs/sitl.md.
 *
 * Where each lives:
 *   effects_rotor.c   rotor_inertia, rotor_gyroscopic, rotor_drag, aero_damping
 *   effects_thrust.c  translational_lift, ground_effect, thrust_nonlinearity
 *   effects_setup.c   com_offset, inertia_error (change the true body once)
 *   effects_sensor.c  esc_delay, gyro_scale (change what the sensors report)
 */
#ifndef SITL_EFFECTS_H
#define SITL_EFFECTS_H

typedef enum {
    SITL_EFFECT_ROTOR_INERTIA = 0,
    SITL_EFFECT_ROTOR_GYROSCOPIC,
    SITL_EFFECT_ROTOR_DRAG,
    SITL_EFFECT_TRANSLATIONAL_LIFT,
    SITL_EFFECT_GROUND_EFFECT,
    SITL_EFFECT_COM_OFFSET,
    SITL_EFFECT_INERTIA_ERROR,
    SITL_EFFECT_ESC_DELAY,
    SITL_EFFECT_THRUST_NONLINEARITY,
    SITL_EFFECT_GYRO_SCALE,
    SITL_EFFECT_AERO_DAMPING,
    SITL_EFFECT_COUNT
} sitl_effect_id_t;

typedef struct {
    const char *name;            /* effect id (--effect NAME, propid gap) */
    double default_strength;     /* used by --effect NAME without =STRENGTH */
    const char *meaning;         /* what the strength is, one line */
} sitl_effect_info_t;

typedef struct {
    int enabled[SITL_EFFECT_COUNT];
    double strength[SITL_EFFECT_COUNT];
} sitl_effects_t;

const sitl_effect_info_t *sitl_effect_info(sitl_effect_id_t id);

/* All off. */
void sitl_effects_clear(sitl_effects_t *effects);

/* Parse "NAME" or "NAME=STRENGTH" and enable it. Returns 0, or -1 with a message. */
int sitl_effects_parse(sitl_effects_t *effects, const char *arg, char *err, int err_size);

/* Every registered effect name joined by separator (for help and messages). */
void sitl_effects_names(char *out, int out_size, const char *separator);

/* Strength if enabled, else 0. */
double sitl_effect_strength(const sitl_effects_t *effects, sitl_effect_id_t id);

/* Comma-separated "name=strength" of the enabled effects ("none" if none). */
void sitl_effects_describe(const sitl_effects_t *effects, char *out, int out_size);

/* Sensor-side effects (effects_sensor.c). */
/* Gyro scale-factor / misalignment matrix: measured = M * true (+ bias, noise). */
void sitl_effects_gyro_matrix(const sitl_effects_t *effects, double m[3][3]);
/* Extra pure delay of the ESC rotor-speed telemetry [s]. */
double sitl_effects_esc_extra_delay(const sitl_effects_t *effects);

#endif /* SITL_EFFECTS_H */
