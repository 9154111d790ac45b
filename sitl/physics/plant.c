/* Rigid body + rotors + ground contact, RK4 (see plant.h). */
#include "plant.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "effects_physics.h"
#include "sitl_math.h"

int sitl_plant_init(sitl_plant_t *plant, const sitl_vehicle_t *vehicle,
                    const double *true_thrust_coeff, const double *true_drag_coeff,
                    const sitl_effects_t *effects, char *err, int err_size)
{
    if (sitl_vehicle_check(vehicle, err, err_size) != 0) {
        return -1;
    }
    memset(plant, 0, sizeof(*plant));
    plant->vehicle = *vehicle;
    if (effects != NULL) {
        plant->effects = *effects;
    }
    plant->gravity = SITL_GRAVITY;
    plant->ground_enabled = 1;
    plant->mass = vehicle->mass;
    memcpy(plant->inertia, vehicle->inertia, sizeof(plant->inertia));
    plant->rotor_count = vehicle->rotor_count;
    double kf_sum = 0.0;
    for (int i = 0; i < vehicle->rotor_count; i++) {
        sitl_vec3_copy(plant->rotor_position[i], vehicle->rotor[i].position);
        plant->yaw_sign[i] = vehicle->rotor[i].yaw_sign;
        plant->thrust_coeff[i] = true_thrust_coeff != NULL ? true_thrust_coeff[i]
                                                           : vehicle->rotor[i].thrust_coeff;
        plant->drag_coeff[i] = true_drag_coeff != NULL ? true_drag_coeff[i]
                                                       : vehicle->rotor[i].drag_coeff;
        if (!(plant->thrust_coeff[i] > 0.0) || !(plant->drag_coeff[i] > 0.0) ||
            !isfinite(plant->thrust_coeff[i]) || !isfinite(plant->drag_coeff[i])) {
            snprintf(err, (size_t)err_size, "true coefficients of rotor %d must be positive",
                     i + 1);
            return -1;
        }
        kf_sum += vehicle->rotor[i].thrust_coeff;
    }
    plant->motor.time_constant = vehicle->motor_time_constant;
    plant->motor.speed_min = vehicle->rotor_speed_min;
    plant->motor.speed_max = vehicle->rotor_speed_max;
    plant->reference_rotor_speed = sqrt(vehicle->mass * plant->gravity / kf_sum);

    sitl_effects_setup_body(plant);
    if (sitl_mat3_inverse(plant->inertia, plant->inertia_inv) != 0) {
        snprintf(err, (size_t)err_size, "true inertia is singular");
        return -1;
    }
    return 0;
}

void sitl_plant_derivative(const sitl_plant_t *plant, const sitl_state_t *state,
                           const double *rotor_command, sitl_state_derivative_t *deriv,
                           sitl_loads_t *loads)
{
    sitl_loads_t local;
    sitl_loads_t *ld = loads != NULL ? loads : &local;
    memset(ld, 0, sizeof(*ld));
    double rot[3][3];
    sitl_quat_to_matrix(state->quat, rot);
    double v_body[3];
    for (int i = 0; i < 3; i++) {
        v_body[i] = rot[0][i] * state->velocity[0] + rot[1][i] * state->velocity[1] +
                    rot[2][i] * state->velocity[2];
    }

    /* With their effects off, the rotor loads are the quadratic law and the
     * effect wrench is zero: skip the hooks (the sums below start at +0, so
     * leaving out += 0 terms changes no bit). */
    const int *on = plant->effects.enabled;
    const int load_effects = on[SITL_EFFECT_THRUST_NONLINEARITY] |
                             on[SITL_EFFECT_TRANSLATIONAL_LIFT] | on[SITL_EFFECT_GROUND_EFFECT];
    const int wrench_effects = on[SITL_EFFECT_ROTOR_INERTIA] | on[SITL_EFFECT_ROTOR_GYROSCOPIC] |
                               on[SITL_EFFECT_ROTOR_DRAG] | on[SITL_EFFECT_AERO_DAMPING];
    for (int i = 0; i < plant->rotor_count; i++) {
        ld->rotor_accel[i] =
            sitl_motor_acceleration(&plant->motor, rotor_command[i], state->rotor_speed[i]);
        deriv->rotor_speed[i] = ld->rotor_accel[i];
        if (load_effects) {
            sitl_effects_rotor_loads(plant, state, v_body, i, &ld->thrust[i], &ld->drag_torque[i]);
        } else {
            const double w = state->rotor_speed[i];
            const double w2 = w * w;
            ld->thrust[i] = plant->thrust_coeff[i] * w2;
            ld->drag_torque[i] = plant->drag_coeff[i] * w2;
        }
        /* Thrust along body z at the hub: force and r x F; drag torque about z. */
        const double *r = plant->rotor_position[i];
        ld->force_body[2] += ld->thrust[i];
        ld->torque_body[0] += r[1] * ld->thrust[i];
        ld->torque_body[1] -= r[0] * ld->thrust[i];
        ld->torque_body[2] += plant->yaw_sign[i] * ld->drag_torque[i];
    }
    if (wrench_effects) {
        double extra_force[3] = {0.0, 0.0, 0.0};
        sitl_effects_rotor_wrench(plant, state, v_body, ld->rotor_accel, extra_force,
                                  ld->effect_torque_body);
        for (int k = 0; k < 3; k++) {
            ld->force_body[k] += extra_force[k];
            ld->torque_body[k] += ld->effect_torque_body[k];
        }
    }

    for (int k = 0; k < 3; k++) {
        if (plant->disturbance_torque[k] != 0.0) {
            ld->torque_body[k] += plant->disturbance_torque[k];
        }
    }

    /* Translation: a = R F / m - g z. */
    double accel[3];
    sitl_mat3_mul_vec(accel, rot, ld->force_body);
    for (int k = 0; k < 3; k++) {
        accel[k] /= plant->mass;
    }
    accel[2] -= plant->gravity;

    /* Rotation: J dw = tau - w x (J w). */
    double jw[3], gyro[3], net[3];
    sitl_mat3_mul_vec(jw, plant->inertia, state->body_rate);
    sitl_vec3_cross(gyro, state->body_rate, jw);
    for (int k = 0; k < 3; k++) {
        net[k] = ld->torque_body[k] - gyro[k];
    }
    sitl_mat3_mul_vec(deriv->body_rate, plant->inertia_inv, net);

    if (state->on_ground && accel[2] <= 0.0) {
        /* Resting on the ground and not lifting off: the contact holds the body. */
        memset(accel, 0, sizeof(accel));
        memset(deriv->body_rate, 0, sizeof(deriv->body_rate));
        memset(deriv->position, 0, sizeof(deriv->position));
        memset(deriv->quat, 0, sizeof(deriv->quat));
    } else {
        sitl_vec3_copy(deriv->position, state->velocity);
        sitl_quat_derivative(state->quat, state->body_rate, deriv->quat);
    }
    sitl_vec3_copy(deriv->velocity, accel);

    /* Accelerometer: specific force = a - g (world), in the body frame. */
    double sf_world[3] = {accel[0], accel[1], accel[2] + plant->gravity};
    for (int i = 0; i < 3; i++) {
        ld->specific_force_body[i] =
            rot[0][i] * sf_world[0] + rot[1][i] * sf_world[1] + rot[2][i] * sf_world[2];
    }
}

/* Effects that change the rotor loads or add a wrench, or a disturbance torque: with none of
 * them, the derivative is the plain rigid body below. */
static int plain_physics(const sitl_plant_t *plant)
{
    const int *on = plant->effects.enabled;
    if (plant->disturbance_torque[0] != 0.0 || plant->disturbance_torque[1] != 0.0 ||
        plant->disturbance_torque[2] != 0.0) {
        return 0;
    }
    return !(on[SITL_EFFECT_THRUST_NONLINEARITY] | on[SITL_EFFECT_TRANSLATIONAL_LIFT] |
             on[SITL_EFFECT_GROUND_EFFECT] | on[SITL_EFFECT_ROTOR_INERTIA] |
             on[SITL_EFFECT_ROTOR_GYROSCOPIC] | on[SITL_EFFECT_ROTOR_DRAG] |
             on[SITL_EFFECT_AERO_DAMPING]);
}

/*
 * sitl_plant_derivative without effects and without the loads, for the RK4
 * stages: the same model, minus what only the loads need (body velocity,
 * specific force) and the products with the zero x/y body force. What does
 * not change while the command is held is taken once (sitl_plant_prepare):
 * the clamped commands, the reciprocals of the motor time constant and of the
 * mass (7 divisions per stage were on the stages' dependent chain), and each
 * rotor's thrust and yaw-torque coefficients times its lever arms. Against
 * sitl_plant_derivative the results differ by rounding only.
 */
#define SITL_INLINE static inline __attribute__((always_inline))

void sitl_plant_prepare(const sitl_plant_t *plant, const double *rotor_command,
                        sitl_plant_prepared_t *c)
{
    memset(c, 0, sizeof(*c));
    const int n = plant->rotor_count;
    memcpy(c->command, rotor_command, (size_t)n * sizeof(double));
    c->plain = plain_physics(plant);
    for (int i = 0; i < n; i++) {
        const double *r = plant->rotor_position[i];
        c->clamped_command[i] = sitl_motor_clamp(&plant->motor, rotor_command[i]);
        c->thrust[i] = plant->thrust_coeff[i];
        c->roll[i] = r[1] * plant->thrust_coeff[i];
        c->pitch[i] = -r[0] * plant->thrust_coeff[i];
        c->yaw[i] = plant->yaw_sign[i] * plant->drag_coeff[i];
    }
    c->inv_time_constant = 1.0 / plant->motor.time_constant;
    c->inv_mass = 1.0 / plant->mass;
    const double (*J)[3] = plant->inertia, (*Ji)[3] = plant->inertia_inv;
    c->diagonal_inertia = J[0][1] == 0.0 && J[0][2] == 0.0 && J[1][0] == 0.0 &&
                          J[1][2] == 0.0 && J[2][0] == 0.0 && J[2][1] == 0.0 &&
                          Ji[0][1] == 0.0 && Ji[0][2] == 0.0 && Ji[1][0] == 0.0 &&
                          Ji[1][2] == 0.0 && Ji[2][0] == 0.0 && Ji[2][1] == 0.0;
}

/* diagonal: a constant where inlined (c->diagonal_inertia picks the copy). */
SITL_INLINE void plain_derivative(const sitl_plant_t *plant, int n, int diagonal,
                                  const sitl_state_t *state, const sitl_plant_prepared_t *c,
                                  sitl_state_derivative_t *deriv)
{
    const double *q = state->quat;
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    /* Third column of the rotation (sitl_quat_to_matrix): where body z points. */
    const double r02 = 2.0 * (x * z + w * y);
    const double r12 = 2.0 * (y * z - w * x);
    const double r22 = 1.0 - 2.0 * (x * x + y * y);

    double force_z = 0.0, torque[3] = {0.0, 0.0, 0.0};
    double speed_sq[SITL_MAX_ROTORS];
    for (int i = 0; i < n; i++) {
        const double speed = state->rotor_speed[i];
        deriv->rotor_speed[i] = (c->clamped_command[i] - speed) * c->inv_time_constant;
        speed_sq[i] = speed * speed;
    }
    if (n == 4) {
        /* Sums in pairs: the loads are on the stages' dependent chain, and two
         * levels of adds are shorter than four (rounding-level difference). */
        force_z = (c->thrust[0] * speed_sq[0] + c->thrust[1] * speed_sq[1]) +
                  (c->thrust[2] * speed_sq[2] + c->thrust[3] * speed_sq[3]);
        torque[0] = (c->roll[0] * speed_sq[0] + c->roll[1] * speed_sq[1]) +
                    (c->roll[2] * speed_sq[2] + c->roll[3] * speed_sq[3]);
        torque[1] = (c->pitch[0] * speed_sq[0] + c->pitch[1] * speed_sq[1]) +
                    (c->pitch[2] * speed_sq[2] + c->pitch[3] * speed_sq[3]);
        torque[2] = (c->yaw[0] * speed_sq[0] + c->yaw[1] * speed_sq[1]) +
                    (c->yaw[2] * speed_sq[2] + c->yaw[3] * speed_sq[3]);
    } else {
        for (int i = 0; i < n; i++) {
            force_z += c->thrust[i] * speed_sq[i];
            torque[0] += c->roll[i] * speed_sq[i];
            torque[1] += c->pitch[i] * speed_sq[i];
            torque[2] += c->yaw[i] * speed_sq[i];
        }
    }

    /* a = R (0, 0, F) / m - g z: the x and y products are +-0 and add nothing. */
    const double specific_thrust = force_z * c->inv_mass;
    double accel[3] = {r02 * specific_thrust, r12 * specific_thrust, r22 * specific_thrust};
    accel[2] -= plant->gravity;

    const double *rate = state->body_rate;
    const double (*J)[3] = plant->inertia;
    double jw[3], net[3];
    if (diagonal) {
        jw[0] = J[0][0] * rate[0];
        jw[1] = J[1][1] * rate[1];
        jw[2] = J[2][2] * rate[2];
    } else {
        sitl_mat3_mul_vec(jw, J, rate);
    }
    net[0] = torque[0] - (rate[1] * jw[2] - rate[2] * jw[1]);
    net[1] = torque[1] - (rate[2] * jw[0] - rate[0] * jw[2]);
    net[2] = torque[2] - (rate[0] * jw[1] - rate[1] * jw[0]);

    if (state->on_ground && accel[2] <= 0.0) {
        memset(deriv->position, 0, sizeof(deriv->position));
        memset(deriv->velocity, 0, sizeof(deriv->velocity));
        memset(deriv->quat, 0, sizeof(deriv->quat));
        memset(deriv->body_rate, 0, sizeof(deriv->body_rate));
        return;
    }
    if (diagonal) {
        const double (*Ji)[3] = plant->inertia_inv;
        deriv->body_rate[0] = Ji[0][0] * net[0];
        deriv->body_rate[1] = Ji[1][1] * net[1];
        deriv->body_rate[2] = Ji[2][2] * net[2];
    } else {
        sitl_mat3_mul_vec(deriv->body_rate, plant->inertia_inv, net);
    }
    sitl_vec3_copy(deriv->position, state->velocity);
    sitl_vec3_copy(deriv->velocity, accel);
    deriv->quat[0] = 0.5 * (-x * rate[0] - y * rate[1] - z * rate[2]);
    deriv->quat[1] = 0.5 * (w * rate[0] + y * rate[2] - z * rate[1]);
    deriv->quat[2] = 0.5 * (w * rate[1] + z * rate[0] - x * rate[2]);
    deriv->quat[3] = 0.5 * (w * rate[2] + x * rate[1] - y * rate[0]);
}

void sitl_plant_specific_force(const sitl_plant_t *plant, const sitl_state_t *state,
                               const double *rotor_command, double specific_force_body[3])
{
    if (!plain_physics(plant)) {
        sitl_state_derivative_t deriv;
        sitl_loads_t loads;
        sitl_plant_derivative(plant, state, rotor_command, &deriv, &loads);
        sitl_vec3_copy(specific_force_body, loads.specific_force_body);
        return;
    }
    /* sitl_plant_derivative's arithmetic for the specific force alone. */
    double rot[3][3];
    sitl_quat_to_matrix(state->quat, rot);
    double force_z = 0.0;
    for (int i = 0; i < plant->rotor_count; i++) {
        const double speed = state->rotor_speed[i];
        force_z += plant->thrust_coeff[i] * (speed * speed);
    }
    double accel[3];
    for (int k = 0; k < 3; k++) {
        accel[k] = rot[k][2] * force_z / plant->mass;
    }
    accel[2] -= plant->gravity;
    if (state->on_ground && accel[2] <= 0.0) {
        memset(accel, 0, sizeof(accel));
    }
    double sf_world[3] = {accel[0], accel[1], accel[2] + plant->gravity};
    for (int i = 0; i < 3; i++) {
        specific_force_body[i] =
            rot[0][i] * sf_world[0] + rot[1][i] * sf_world[1] + rot[2][i] * sf_world[2];
    }
}

/* out = base + h d over the integrated fields (on_ground is carried). */
SITL_INLINE void add_scaled(int rotor_count, const sitl_state_t *base,
                       const sitl_state_derivative_t *d, double h, sitl_state_t *out)
{
    for (int k = 0; k < 3; k++) {
        out->position[k] = base->position[k] + h * d->position[k];
        out->velocity[k] = base->velocity[k] + h * d->velocity[k];
        out->body_rate[k] = base->body_rate[k] + h * d->body_rate[k];
    }
    for (int k = 0; k < 4; k++) {
        out->quat[k] = base->quat[k] + h * d->quat[k];
    }
    for (int i = 0; i < rotor_count; i++) {
        out->rotor_speed[i] = base->rotor_speed[i] + h * d->rotor_speed[i];
    }
    out->on_ground = base->on_ground;
}

/* The four stages without effects; n and diagonal are constants where it is
 * inlined, so the rotor loops unroll and the inertia products shrink. */
SITL_INLINE void plain_stages(const sitl_plant_t *plant, int n, int diagonal,
                              const sitl_state_t *state, const sitl_plant_prepared_t *c, double dt,
                              sitl_state_derivative_t k[4])
{
    sitl_state_t tmp;
    plain_derivative(plant, n, diagonal, state, c, &k[0]);
    add_scaled(n, state, &k[0], 0.5 * dt, &tmp);
    plain_derivative(plant, n, diagonal, &tmp, c, &k[1]);
    add_scaled(n, state, &k[1], 0.5 * dt, &tmp);
    plain_derivative(plant, n, diagonal, &tmp, c, &k[2]);
    add_scaled(n, state, &k[2], dt, &tmp);
    plain_derivative(plant, n, diagonal, &tmp, c, &k[3]);
}

void sitl_plant_step(const sitl_plant_t *plant, sitl_state_t *state, const double *rotor_command,
                     double dt)
{
    sitl_plant_prepared_t prepared;
    sitl_plant_prepare(plant, rotor_command, &prepared);
    sitl_plant_step_prepared(plant, &prepared, state, dt);
}

/* The four stages of one RK4 step from state (either derivative). */
SITL_INLINE void rk4_stages(const sitl_plant_t *plant, const sitl_plant_prepared_t *c,
                            const sitl_state_t *state, double dt, sitl_state_derivative_t stage[4])
{
    const int n = plant->rotor_count;
    if (c->plain) {
        if (n == 4 && c->diagonal_inertia) {
            plain_stages(plant, 4, 1, state, c, dt, stage);
        } else {
            plain_stages(plant, n, 0, state, c, dt, stage);
        }
    } else {
        const double *rotor_command = c->command;
        sitl_state_t tmp;
        sitl_plant_derivative(plant, state, rotor_command, &stage[0], NULL);
        add_scaled(n, state, &stage[0], 0.5 * dt, &tmp);
        sitl_plant_derivative(plant, &tmp, rotor_command, &stage[1], NULL);
        add_scaled(n, state, &stage[1], 0.5 * dt, &tmp);
        sitl_plant_derivative(plant, &tmp, rotor_command, &stage[2], NULL);
        add_scaled(n, state, &stage[2], dt, &tmp);
        sitl_plant_derivative(plant, &tmp, rotor_command, &stage[3], NULL);
    }
}

/* state <- the RK4 step's end from its stages, normalised, clamped, on the ground. */
SITL_INLINE void rk4_finish(const sitl_plant_t *plant, const sitl_state_derivative_t stage[4],
                            sitl_state_t *state, double dt)
{
    const int n = plant->rotor_count;
    const sitl_state_derivative_t *k1 = &stage[0], *k2 = &stage[1], *k3 = &stage[2],
                                  *k4 = &stage[3];

    const double w = dt / 6.0;
    for (int k = 0; k < 3; k++) {
        state->position[k] += w * (k1->position[k] + 2.0 * k2->position[k] + 2.0 * k3->position[k] +
                                   k4->position[k]);
        state->velocity[k] += w * (k1->velocity[k] + 2.0 * k2->velocity[k] + 2.0 * k3->velocity[k] +
                                   k4->velocity[k]);
        state->body_rate[k] += w * (k1->body_rate[k] + 2.0 * k2->body_rate[k] +
                                    2.0 * k3->body_rate[k] + k4->body_rate[k]);
    }
    for (int k = 0; k < 4; k++) {
        state->quat[k] += w * (k1->quat[k] + 2.0 * k2->quat[k] + 2.0 * k3->quat[k] + k4->quat[k]);
    }
    for (int i = 0; i < n; i++) {
        state->rotor_speed[i] += w * (k1->rotor_speed[i] + 2.0 * k2->rotor_speed[i] +
                                      2.0 * k3->rotor_speed[i] + k4->rotor_speed[i]);
        state->rotor_speed[i] = sitl_motor_clamp(&plant->motor, state->rotor_speed[i]);
    }
    sitl_quat_normalise(state->quat);

    if (plant->ground_enabled) {
        if (state->position[2] <= 0.0 && (state->velocity[2] <= 0.0 || state->on_ground)) {
            /* Touch-down or resting: inelastic contact with full friction. */
            state->position[2] = 0.0;
            memset(state->velocity, 0, sizeof(state->velocity));
            memset(state->body_rate, 0, sizeof(state->body_rate));
            state->on_ground = 1;
        } else if (state->position[2] > 0.0) {
            state->on_ground = 0;
        }
    }
}

void sitl_plant_step_prepared(const sitl_plant_t *plant, const sitl_plant_prepared_t *c,
                              sitl_state_t *state, double dt)
{
    sitl_state_derivative_t stage[4];
    rk4_stages(plant, c, state, dt, stage);
    rk4_finish(plant, stage, state, dt);
}

void sitl_plant_step_prepared_sampled(const sitl_plant_t *plant, const sitl_plant_prepared_t *c,
                                      sitl_state_t *state, double dt, double theta,
                                      sitl_state_t *sample)
{
    sitl_state_derivative_t stage[4];
    rk4_stages(plant, c, state, dt, stage);
    /* Classic RK4's free continuous extension (third order, from the stages alone). */
    const double t2 = theta * theta, t3 = t2 * theta;
    const double b1 = dt * (theta - 1.5 * t2 + (2.0 / 3.0) * t3);
    const double b23 = dt * (t2 - (2.0 / 3.0) * t3);
    const double b4 = dt * (-0.5 * t2 + (2.0 / 3.0) * t3);
    const sitl_state_derivative_t *k1 = &stage[0], *k2 = &stage[1], *k3 = &stage[2],
                                  *k4 = &stage[3];
    for (int k = 0; k < 3; k++) {
        sample->position[k] = state->position[k] + (b1 * k1->position[k] +
                              b23 * (k2->position[k] + k3->position[k]) + b4 * k4->position[k]);
        sample->velocity[k] = state->velocity[k] + (b1 * k1->velocity[k] +
                              b23 * (k2->velocity[k] + k3->velocity[k]) + b4 * k4->velocity[k]);
        sample->body_rate[k] = state->body_rate[k] + (b1 * k1->body_rate[k] +
                               b23 * (k2->body_rate[k] + k3->body_rate[k]) + b4 * k4->body_rate[k]);
    }
    for (int k = 0; k < 4; k++) {
        sample->quat[k] = state->quat[k] +
                          (b1 * k1->quat[k] + b23 * (k2->quat[k] + k3->quat[k]) + b4 * k4->quat[k]);
    }
    for (int i = 0; i < plant->rotor_count; i++) {
        sample->rotor_speed[i] = sitl_motor_clamp(
            &plant->motor, state->rotor_speed[i] + (b1 * k1->rotor_speed[i] +
                                                    b23 * (k2->rotor_speed[i] + k3->rotor_speed[i]) +
                                                    b4 * k4->rotor_speed[i]));
    }
    sitl_quat_normalise(sample->quat);
    sample->on_ground = state->on_ground;
    rk4_finish(plant, stage, state, dt);
}

int sitl_plant_hover_speeds(const sitl_plant_t *plant, double *rotor_speed)
{
    const int n = plant->rotor_count;
    double a[4][SITL_MAX_ROTORS];
    for (int i = 0; i < n; i++) {
        const double *r = plant->rotor_position[i];
        double kf = plant->thrust_coeff[i];
        a[0][i] = kf;
        a[1][i] = r[1] * kf;
        a[2][i] = -r[0] * kf;
        a[3][i] = plant->yaw_sign[i] * plant->drag_coeff[i];
    }
    /* Rows are scaled to comparable magnitude before the min-norm solve. */
    double scale[4];
    for (int r = 0; r < 4; r++) {
        double s = 0.0;
        for (int i = 0; i < n; i++) {
            s += a[r][i] * a[r][i];
        }
        scale[r] = s > 0.0 ? 1.0 / sqrt(s) : 1.0;
        for (int i = 0; i < n; i++) {
            a[r][i] *= scale[r];
        }
    }
    double aat[4][4], y[4][4] = {{plant->mass * plant->gravity * scale[0]}};
    for (int r = 0; r < 4; r++) {
        for (int c = 0; c < 4; c++) {
            double s = 0.0;
            for (int i = 0; i < n; i++) {
                s += a[r][i] * a[c][i];
            }
            aat[r][c] = s;
        }
    }
    double aat_copy[4][4], y_copy[4][4];
    memcpy(aat_copy, aat, sizeof(aat));
    memcpy(y_copy, y, sizeof(y));
    /* Rows are normalised: entries ~1, so the pivot tolerance is absolute. */
    int ok = sitl_mat4_solve(aat, y, 1, 1e-12) == 0;
    if (!ok) {
        /* N < 4 (or a degenerate layout): a tiny ridge gives the closest try. */
        for (int r = 0; r < 4; r++) {
            aat_copy[r][r] += 1e-9;
        }
        memcpy(y, y_copy, sizeof(y));
        ok = sitl_mat4_solve(aat_copy, y, 1, 1e-12) == 0;
    }
    int feasible = ok;
    for (int i = 0; i < n; i++) {
        double u = 0.0;
        for (int r = 0; r < 4; r++) {
            u += a[r][i] * y[r][0];
        }
        if (!ok || !(u >= 0.0)) {
            u = ok ? 0.0 : plant->mass * plant->gravity / ((double)n * plant->thrust_coeff[i]);
            feasible = 0;
        }
        double speed = sqrt(u);
        if (speed > plant->motor.speed_max || speed < plant->motor.speed_min) {
            feasible = 0;
        }
        rotor_speed[i] = sitl_motor_clamp(&plant->motor, speed);
    }
    return feasible ? 0 : -1;
}

void sitl_plant_hover_state(const sitl_plant_t *plant, const double position[3], double yaw,
                            sitl_state_t *state)
{
    memset(state, 0, sizeof(*state));
    sitl_vec3_copy(state->position, position);
    sitl_quat_from_yaw(yaw, state->quat);
    sitl_plant_hover_speeds(plant, state->rotor_speed);
    state->on_ground = plant->ground_enabled && position[2] <= 0.0;
}
