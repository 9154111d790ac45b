/* Effect registry: names, default strengths, parsing (see effects.h). */
#include "effects.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const sitl_effect_info_t infos[SITL_EFFECT_COUNT] = {
    [SITL_EFFECT_ROTOR_INERTIA] = {"rotor_inertia", 1.0,
                                   "multiplier of the vehicle's rotor inertia"},
    [SITL_EFFECT_ROTOR_GYROSCOPIC] = {"rotor_gyroscopic", 1.0,
                                      "multiplier of the vehicle's rotor inertia"},
    [SITL_EFFECT_ROTOR_DRAG] = {"rotor_drag", 1.0,
                                "multiplier of the vehicle's k_d, k_z and k_flap"},
    [SITL_EFFECT_TRANSLATIONAL_LIFT] = {"translational_lift", 1.0,
                                        "multiplier of the vehicle's k_h"},
    [SITL_EFFECT_GROUND_EFFECT] = {"ground_effect", 1.0,
                                   "multiplier of the Cheeseman-Bennett thrust gain"},
    [SITL_EFFECT_COM_OFFSET] = {"com_offset", 0.05,
                                "CoM offset as a fraction of the arm length"},
    [SITL_EFFECT_INERTIA_ERROR] = {"inertia_error", 0.1,
                                   "relative error of the file's inertia (true = file*(1+s))"},
    [SITL_EFFECT_ESC_DELAY] = {"esc_delay", 0.02, "extra telemetry delay [s]"},
    [SITL_EFFECT_THRUST_NONLINEARITY] = {"thrust_nonlinearity", 0.1,
                                         "extra exponent: T = kf w^2 (w/w_hover)^s"},
    [SITL_EFFECT_GYRO_SCALE] = {"gyro_scale", 0.02,
                                "scale-factor error; misalignment s/2 [rad]"},
    [SITL_EFFECT_AERO_DAMPING] = {"aero_damping", 1.0,
                                  "multiplier of rotor drag from body rotation"},
};

const sitl_effect_info_t *sitl_effect_info(sitl_effect_id_t id)
{
    if ((int)id < 0 || id >= SITL_EFFECT_COUNT) {
        return NULL;
    }
    return &infos[id];
}

void sitl_effects_clear(sitl_effects_t *effects)
{
    memset(effects, 0, sizeof(*effects));
}

int sitl_effects_parse(sitl_effects_t *effects, const char *arg, char *err, int err_size)
{
    char scratch[8];
    if (err == NULL || err_size <= 0) { /* caller does not want the message */
        err = scratch;
        err_size = (int)sizeof(scratch);
    }
    char name[64];
    const char *eq = strchr(arg, '=');
    size_t len = eq != NULL ? (size_t)(eq - arg) : strlen(arg);
    if (len == 0 || len >= sizeof(name)) {
        snprintf(err, (size_t)err_size, "--effect: bad effect '%s'", arg);
        return -1;
    }
    memcpy(name, arg, len);
    name[len] = '\0';
    if (strcmp(name, "none") == 0 && eq == NULL) {
        sitl_effects_clear(effects);
        return 0;
    }
    for (int i = 0; i < SITL_EFFECT_COUNT; i++) {
        if (strcmp(name, infos[i].name) != 0) {
            continue;
        }
        double strength = infos[i].default_strength;
        if (eq != NULL) {
            char *end = NULL;
            strength = strtod(eq + 1, &end);
            if (end == eq + 1 || *end != '\0' || !isfinite(strength)) {
                snprintf(err, (size_t)err_size, "--effect %s: strength '%s' is not a number",
                         name, eq + 1);
                return -1;
            }
        }
        effects->enabled[i] = 1;
        effects->strength[i] = strength;
        return 0;
    }
    int n = snprintf(err, (size_t)err_size, "--effect: unknown effect '%s' (known:", name);
    for (int i = 0; i < SITL_EFFECT_COUNT && n > 0 && n < err_size; i++) {
        n += snprintf(err + n, (size_t)(err_size - n), " %s", infos[i].name);
    }
    if (n > 0 && n < err_size) {
        snprintf(err + n, (size_t)(err_size - n), ")");
    }
    return -1;
}

void sitl_effects_names(char *out, int out_size, const char *separator)
{
    int n = 0;
    out[0] = '\0';
    for (int i = 0; i < SITL_EFFECT_COUNT && n >= 0 && n < out_size; i++) {
        n += snprintf(out + n, (size_t)(out_size - n), "%s%s", i ? separator : "", infos[i].name);
    }
}

double sitl_effect_strength(const sitl_effects_t *effects, sitl_effect_id_t id)
{
    if (effects == NULL || (int)id < 0 || id >= SITL_EFFECT_COUNT || !effects->enabled[id]) {
        return 0.0;
    }
    return effects->strength[id];
}

void sitl_effects_describe(const sitl_effects_t *effects, char *out, int out_size)
{
    int n = 0;
    out[0] = '\0';
    for (int i = 0; i < SITL_EFFECT_COUNT; i++) {
        if (effects->enabled[i] && n >= 0 && n < out_size) {
            n += snprintf(out + n, (size_t)(out_size - n), "%s%s=%g", n ? "," : "", infos[i].name,
                          effects->strength[i]);
        }
    }
    if (n == 0) {
        snprintf(out, (size_t)out_size, "none");
    }
}
