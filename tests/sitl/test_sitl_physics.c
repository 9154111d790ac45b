/*
 * Plant physics: free fall, hover equilibrium, torque signs of the plus and
 * X layouts, motor lag, torque-free rigid-body rotation (RK4 quality), ground
 * contact and take-off, physics-rate independence, one preparation held
 * over many steps, the state read inside a step.
 */
#include <math.h>
#include <string.h>

#include "physics_rate.h"
#include "plant.h"
#include "sitl_math.h"
#include "unity.h"

static sitl_plant_t plant;
static sitl_vehicle_t vehicle;

static void make_plant(const char *preset)
{
    char err[256];
    TEST_ASSERT_EQUAL_INT(0, sitl_vehicle_preset(preset, &vehicle));
    TEST_ASSERT_EQUAL_INT_MESSAGE(0, sitl_plant_init(&plant, &vehicle, NULL, NULL, NULL, err,
                                                     (int)sizeof(err)),
                                  err);
}

void setUp(void)
{
    make_plant("crazyflie-plus");
}

void tearDown(void)
{
}

static void fly(sitl_state_t *s, const double *cmd, double seconds, double dt)
{
    long steps = lround(seconds / dt);
    for (long k = 0; k < steps; k++) {
        sitl_plant_step(&plant, s, cmd, dt);
    }
}

static void test_free_fall_is_exact(void)
{
    plant.ground_enabled = 0;
    sitl_state_t s;
    memset(&s, 0, sizeof(s));
    s.quat[0] = 1.0;
    s.position[2] = 10.0;
    double cmd[SITL_MAX_ROTORS] = {0};
    fly(&s, cmd, 1.0, 0.0005);
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, 10.0 - 0.5 * SITL_GRAVITY, s.position[2]);
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, -SITL_GRAVITY, s.velocity[2]);
}

static void test_hover_speeds_hold_the_vehicle(void)
{
    const char *presets[4] = {"crazyflie-plus", "crazyflie-x", "hummingbird-plus",
                              "hummingbird-x"};
    for (int p = 0; p < 4; p++) {
        make_plant(presets[p]);
        /* Unequal true coefficients: hover needs unequal speeds. */
        double kf[4] = {2.1e-8, 2.5e-8, 2.2e-8, 2.4e-8};
        double km[4] = {7.0e-10, 8.5e-10, 7.5e-10, 8.0e-10};
        if (p >= 2) {
            for (int i = 0; i < 4; i++) {
                kf[i] *= 5.57e-6 / 2.3e-8;
                km[i] *= 1.36e-7 / 7.8e-10;
            }
        }
        char err[256];
        TEST_ASSERT_EQUAL_INT(0, sitl_plant_init(&plant, &vehicle, kf, km, NULL, err, 256));
        sitl_state_t s;
        double pos[3] = {1.0, 2.0, 3.0};
        sitl_plant_hover_state(&plant, pos, 0.3, &s);
        double cmd[SITL_MAX_ROTORS];
        memcpy(cmd, s.rotor_speed, sizeof(cmd));
        fly(&s, cmd, 2.0, 0.0005);
        TEST_ASSERT_DOUBLE_WITHIN(1e-9, 3.0, s.position[2]);
        TEST_ASSERT_DOUBLE_WITHIN(1e-9, 1.0, s.position[0]);
        TEST_ASSERT_DOUBLE_WITHIN(1e-9, 0.0, s.body_rate[2]);
        TEST_ASSERT_DOUBLE_WITHIN(1e-9, 0.0, s.body_rate[0]);
    }
}

/* Angular acceleration when one rotor runs 10 % above the others. */
static void one_rotor_faster(int rotor, double dw[3])
{
    sitl_state_t s;
    double pos[3] = {0.0, 0.0, 1.0};
    sitl_plant_hover_state(&plant, pos, 0.0, &s);
    s.rotor_speed[rotor] *= 1.1;
    sitl_state_derivative_t d;
    sitl_plant_derivative(&plant, &s, s.rotor_speed, &d, NULL);
    sitl_vec3_copy(dw, d.body_rate);
}

static void test_plus_layout_torque_signs(void)
{
    double dw[3];
    /* Rotor 1 on +x: more thrust there pitches the nose up = negative y (FLU). */
    one_rotor_faster(0, dw);
    TEST_ASSERT_TRUE(dw[1] < 0.0);
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, 0.0, dw[0]);
    TEST_ASSERT_TRUE(dw[2] > 0.0); /* yaw_sign + */
    /* Rotor 2 on +y: rolls right side down = positive x. */
    one_rotor_faster(1, dw);
    TEST_ASSERT_TRUE(dw[0] > 0.0);
    TEST_ASSERT_TRUE(dw[2] < 0.0); /* yaw_sign - */
    /* Magnitude: L * kf * dOmega^2 / Jxx. */
    sitl_state_t s;
    double pos[3] = {0.0, 0.0, 1.0};
    sitl_plant_hover_state(&plant, pos, 0.0, &s);
    double w = s.rotor_speed[1];
    double expected = 0.043 * 2.3e-8 * (1.21 - 1.0) * w * w / 1.43e-5;
    TEST_ASSERT_DOUBLE_WITHIN(1e-9 * expected, expected, dw[0]);
}

static void test_x_layout_geometry(void)
{
    make_plant("crazyflie-x");
    double a = 0.043 / sqrt(2.0);
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, a, vehicle.rotor[0].position[0]);
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, a, vehicle.rotor[0].position[1]);
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, -a, vehicle.rotor[1].position[0]); /* CCW: rotor 2 front-left -> back-left */
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, a, vehicle.rotor[1].position[1]);
    double dw[3];
    one_rotor_faster(0, dw); /* front-left: roll positive, pitch nose-up (negative) */
    TEST_ASSERT_TRUE(dw[0] > 0.0);
    TEST_ASSERT_TRUE(dw[1] < 0.0);
}

static void test_motor_first_order_lag(void)
{
    sitl_state_t s;
    double pos[3] = {0.0, 0.0, 100.0};
    sitl_plant_hover_state(&plant, pos, 0.0, &s);
    double w0 = s.rotor_speed[0];
    double cmd[SITL_MAX_ROTORS];
    memcpy(cmd, s.rotor_speed, sizeof(cmd));
    cmd[0] = w0 + 500.0;
    fly(&s, cmd, 0.072, 0.0001); /* one time constant */
    TEST_ASSERT_DOUBLE_WITHIN(0.5, w0 + 500.0 * (1.0 - exp(-1.0)), s.rotor_speed[0]);
    cmd[0] = 1e6; /* beyond the limit */
    fly(&s, cmd, 2.0, 0.0005);
    TEST_ASSERT_TRUE(s.rotor_speed[0] <= 2500.0);
    TEST_ASSERT_DOUBLE_WITHIN(1.0, 2500.0, s.rotor_speed[0]);
}

static void test_torque_free_rotation_conserves_energy_and_momentum(void)
{
    plant.ground_enabled = 0;
    plant.gravity = 0.0;
    sitl_state_t s;
    memset(&s, 0, sizeof(s));
    s.quat[0] = 1.0;
    s.position[2] = 1.0;
    sitl_vec3_set(s.body_rate, 3.0, 0.5, 2.0);
    double cmd[SITL_MAX_ROTORS] = {0};
    double jw[3], h0[3], e0;
    sitl_mat3_mul_vec(jw, plant.inertia, s.body_rate);
    sitl_quat_rotate(s.quat, jw, h0);
    e0 = 0.5 * sitl_vec3_dot(s.body_rate, jw);
    fly(&s, cmd, 5.0, 0.0005);
    double h1[3];
    sitl_mat3_mul_vec(jw, plant.inertia, s.body_rate);
    sitl_quat_rotate(s.quat, jw, h1);
    double e1 = 0.5 * sitl_vec3_dot(s.body_rate, jw);
    TEST_ASSERT_DOUBLE_WITHIN(1e-8 * e0, e0, e1);
    for (int k = 0; k < 3; k++) {
        TEST_ASSERT_DOUBLE_WITHIN(1e-8 * sitl_vec3_norm(h0), h0[k], h1[k]);
    }
}

static void test_ground_holds_and_releases(void)
{
    sitl_state_t s;
    double pos[3] = {0.0, 0.0, 0.0};
    sitl_plant_hover_state(&plant, pos, 0.0, &s);
    memset(s.rotor_speed, 0, sizeof(s.rotor_speed));
    s.on_ground = 1;
    double cmd[SITL_MAX_ROTORS] = {0};
    fly(&s, cmd, 1.0, 0.0005);
    TEST_ASSERT_EQUAL_DOUBLE(0.0, s.position[2]);
    TEST_ASSERT_EQUAL_INT(1, s.on_ground);
    /* Thrust 1.5 x weight: lifts off. */
    double w = sqrt(1.5 * 0.03 * SITL_GRAVITY / (4.0 * 2.3e-8));
    for (int i = 0; i < 4; i++) {
        cmd[i] = w;
    }
    fly(&s, cmd, 1.0, 0.0005);
    TEST_ASSERT_TRUE(s.position[2] > 0.5);
    TEST_ASSERT_EQUAL_INT(0, s.on_ground);
    /* Rotors off again: falls back and stops at z = 0, never below. */
    memset(cmd, 0, sizeof(cmd));
    for (int k = 0; k < 6000; k++) {
        sitl_plant_step(&plant, &s, cmd, 0.0005);
        TEST_ASSERT_TRUE(s.position[2] >= 0.0);
    }
    TEST_ASSERT_EQUAL_INT(1, s.on_ground);
}

static void test_step_size_independence(void)
{
    /* The same manoeuvre at 2 kHz and 10 kHz agrees to RK4 accuracy. */
    sitl_state_t a, b;
    double pos[3] = {0.0, 0.0, 5.0};
    sitl_plant_hover_state(&plant, pos, 0.0, &a);
    b = a;
    double cmd[SITL_MAX_ROTORS];
    memcpy(cmd, a.rotor_speed, sizeof(cmd));
    cmd[1] *= 1.02;
    cmd[0] *= 0.99;
    fly(&a, cmd, 0.5, 0.0005);
    fly(&b, cmd, 0.5, 0.0001);
    for (int k = 0; k < 3; k++) {
        TEST_ASSERT_DOUBLE_WITHIN(1e-6, b.position[k], a.position[k]);
        TEST_ASSERT_DOUBLE_WITHIN(1e-5, b.body_rate[k], a.body_rate[k]);
    }
}

/* The physics step's rule (physics_rate.h): the smallest multiple of the control
 * rate with h <= tau_m / 10 and h <= 0.1 / (2000 deg/s). */
static void test_physics_rate_rule(void)
{
    TEST_ASSERT_EQUAL_DOUBLE(500.0, sitl_physics_rate_for(0.072, 500.0));  /* Crazyflie */
    TEST_ASSERT_EQUAL_DOUBLE(2000.0, sitl_physics_rate_for(0.005, 500.0)); /* Hummingbird, exact */
    TEST_ASSERT_EQUAL_DOUBLE(2500.0, sitl_physics_rate_for(0.0049, 500.0));
    TEST_ASSERT_EQUAL_DOUBLE(500.0, sitl_physics_rate_for(0.03, 500.0));   /* file without motor data */
    /* the attitude bound: 349 Hz needs two steps per 300 Hz control period */
    TEST_ASSERT_EQUAL_DOUBLE(600.0, sitl_physics_rate_for(0.072, 300.0));
    TEST_ASSERT_EQUAL_DOUBLE(1000.0, sitl_physics_rate_for(0.072, 1000.0));
    TEST_ASSERT_EQUAL_DOUBLE(0.0, sitl_physics_rate_for(0.0, 500.0));
    TEST_ASSERT_EQUAL_DOUBLE(0.0, sitl_physics_rate_for(NAN, 500.0));
    TEST_ASSERT_EQUAL_DOUBLE(0.0, sitl_physics_rate_for(0.072, -1.0));
    TEST_ASSERT_EQUAL_DOUBLE(0.0, sitl_physics_rate_for(INFINITY, 500.0));
}

/* What the rule promises: at its step, on every preset, a full-range motor step (rotors
 * stopped, command at the top speed) stays within 8.4e-7 of the speed range of the exact
 * first-order response at every step; the next coarser multiple of the control rate
 * breaks one of the rule's bounds. */
static void test_physics_rate_rule_bounds_the_motor_error(void)
{
    for (int p = 0; sitl_vehicle_preset_names[p] != NULL; p++) {
        make_plant(sitl_vehicle_preset_names[p]);
        plant.ground_enabled = 0;
        const double tau = vehicle.motor_time_constant;
        const double rate = sitl_physics_rate_for(tau, 500.0);
        TEST_ASSERT_TRUE(rate >= 500.0);
        const double h = 1.0 / rate;
        TEST_ASSERT_TRUE(h <= 0.1 * tau * (1.0 + 1e-12));
        if (rate > 500.0) {
            TEST_ASSERT_TRUE(1.0 / (rate - 500.0) > 0.1 * tau);
        }
        sitl_state_t s;
        memset(&s, 0, sizeof(s));
        s.quat[0] = 1.0;
        s.position[2] = 100.0;
        double cmd[SITL_MAX_ROTORS];
        for (int i = 0; i < SITL_MAX_ROTORS; i++) {
            cmd[i] = vehicle.rotor_speed_max;
        }
        const double range = vehicle.rotor_speed_max - vehicle.rotor_speed_min;
        double worst = 0.0;
        for (int k = 1; k <= (int)lround(5.0 * tau / h); k++) {
            sitl_plant_step(&plant, &s, cmd, h);
            const double exact = vehicle.rotor_speed_max * (1.0 - exp(-(double)k * h / tau));
            for (int i = 0; i < vehicle.rotor_count; i++) {
                worst = fmax(worst, fabs(s.rotor_speed[i] - exact));
            }
        }
        TEST_ASSERT_TRUE_MESSAGE(worst <= 8.4e-7 * range, sitl_vehicle_preset_names[p]);
    }
}

/* The three paths the prepared steps take (a quad plus, the general rotor-count path,
 * a quad X with the effects' derivative, rotor_drag): the plant of path p and its
 * hover state at 2 m, moving forward at 0.5 m/s. */
static const char *const step_path_presets[3] = {"crazyflie-plus", "hexa-x", "crazyflie-x"};

static void make_step_path_plant(int p, sitl_state_t *start)
{
    char err[256];
    sitl_effects_t effects;
    sitl_effects_clear(&effects);
    if (p == 2) {
        TEST_ASSERT_EQUAL_INT(0, sitl_effects_parse(&effects, "rotor_drag", err, (int)sizeof(err)));
    }
    TEST_ASSERT_EQUAL_INT(0, sitl_vehicle_preset(step_path_presets[p], &vehicle));
    TEST_ASSERT_EQUAL_INT(0, sitl_plant_init(&plant, &vehicle, NULL, NULL, &effects, err,
                                             (int)sizeof(err)));
    double pos[3] = {0.0, 0.0, 2.0};
    sitl_plant_hover_state(&plant, pos, 0.3, start);
    start->velocity[0] = 0.5;
}

/* Rotor commands off hover: rotor i driven (i + 1) * spread of its hover speed up
 * (even i) or down (odd i), so the vehicle turns and the motors move. */
static void off_hover_command(double cmd[SITL_MAX_ROTORS], const sitl_state_t *hover,
                              double spread)
{
    memcpy(cmd, hover->rotor_speed, sizeof(hover->rotor_speed));
    for (int i = 0; i < vehicle.rotor_count; i++) {
        cmd[i] *= 1.0 + spread * (double)(i + 1) * (i % 2 ? -1.0 : 1.0);
    }
}

/* Two states bit for bit the same: position, velocity, attitude, body rate, rotor speeds. */
static void assert_same_state(const sitl_state_t *expected, const sitl_state_t *actual,
                              const char *name)
{
    TEST_ASSERT_EQUAL_MEMORY_MESSAGE(expected->position, actual->position,
                                     sizeof(actual->position), name);
    TEST_ASSERT_EQUAL_MEMORY_MESSAGE(expected->velocity, actual->velocity,
                                     sizeof(actual->velocity), name);
    TEST_ASSERT_EQUAL_MEMORY_MESSAGE(expected->quat, actual->quat, sizeof(actual->quat), name);
    TEST_ASSERT_EQUAL_MEMORY_MESSAGE(expected->body_rate, actual->body_rate,
                                     sizeof(actual->body_rate), name);
    TEST_ASSERT_EQUAL_MEMORY_MESSAGE(expected->rotor_speed, actual->rotor_speed,
                                     sizeof(actual->rotor_speed), name);
}

/* A flight prepares the plant once per command (sitl_plant_prepare) and steps
 * it several times with unequal steps: the state is the one sitl_plant_step
 * gives (which prepares at every call), bit for bit, on the quad path, the
 * general rotor-count path and the effects' derivative. */
static void test_prepared_steps_match_plain_steps(void)
{
    const char *const *presets = step_path_presets;
    for (int p = 0; p < 3; p++) {
        sitl_state_t a, b;
        make_step_path_plant(p, &a);
        a.body_rate[1] = 0.2;
        b = a;
        double cmd[SITL_MAX_ROTORS];
        off_hover_command(cmd, &a, 0.01);
        sitl_plant_prepared_t prepared;
        sitl_plant_prepare(&plant, cmd, &prepared);
        for (int k = 0; k < 40; k++) {
            const double dt = k % 3 == 0 ? 0.00025 : 0.0005;
            sitl_plant_step(&plant, &a, cmd, dt);
            sitl_plant_step_prepared(&plant, &prepared, &b, dt);
        }
        assert_same_state(&a, &b, presets[p]);
        TEST_ASSERT_EQUAL_INT(a.on_ground, b.on_ground);
        TEST_ASSERT_TRUE(a.position[0] > 0.005); /* it moved */
    }
}

/* A step that also reads the state inside it (sitl_plant_step_prepared_sampled, for an
 * IMU sample within the step) ends where the plain step ends, bit for bit, on the quad
 * path, the general rotor-count path and the effects' derivative; its sample is the
 * step's continuous extension: against a fine reference (64 steps to the instant), on a
 * turning vehicle whose rotors are driven 5-30 % off hover (up to ~ 560 rad/s), the body
 * rate within 2e-7 rad/s (measured 5e-8: (5/384) h^4 |w^(4)|, docs/sitl.md "The loop"),
 * the attitude within 1e-8, the position within 1e-9 m, the rotor speeds within 1e-5 rad/s
 * (measured 4e-6); the start state instead would be off by the 1 ms of motion
 * (at least 6e-4 rad/s and 3.8 rad/s here). */
static void test_sampled_step_ends_like_the_plain_step(void)
{
    const char *const *presets = step_path_presets;
    for (int p = 0; p < 3; p++) {
        sitl_state_t a, b;
        make_step_path_plant(p, &a);
        a.body_rate[0] = -0.4;
        a.body_rate[1] = 0.2;
        double cmd[SITL_MAX_ROTORS];
        off_hover_command(cmd, &a, 0.05);
        sitl_plant_prepared_t prepared;
        sitl_plant_prepare(&plant, cmd, &prepared);
        const double h = 0.002;
        for (int k = 0; k < 10; k++) {
            b = a;
            sitl_state_t sample, reference = a;
            sitl_plant_step_prepared_sampled(&plant, &prepared, &a, h, 0.5, &sample);
            sitl_plant_step_prepared(&plant, &prepared, &b, h);
            for (int j = 0; j < 64; j++) {
                sitl_plant_step_prepared(&plant, &prepared, &reference, 0.5 * h / 64.0);
            }
            assert_same_state(&b, &a, presets[p]);
            for (int c = 0; c < 3; c++) {
                TEST_ASSERT_DOUBLE_WITHIN(2e-7, reference.body_rate[c], sample.body_rate[c]);
                TEST_ASSERT_DOUBLE_WITHIN(1e-9, reference.position[c], sample.position[c]);
            }
            for (int c = 0; c < 4; c++) {
                TEST_ASSERT_DOUBLE_WITHIN(1e-8, reference.quat[c], sample.quat[c]);
            }
            for (int i = 0; i < vehicle.rotor_count; i++) {
                TEST_ASSERT_DOUBLE_WITHIN(1e-5, reference.rotor_speed[i], sample.rotor_speed[i]);
            }
        }
        TEST_ASSERT_TRUE(fabs(a.body_rate[0] + 0.4) > 1e-3); /* it turned */
    }
}

/* On the motor's linear lag the sample's error is exactly the continuous extension's:
 * Omega(t + theta h) errs by c(theta) z^4 |drive| + O(z^5), z = h / tau_m, with
 * c = 11/2048, 5/384, 27/2048 at theta = 1/4, 1/2, 3/4 (the stages' polynomial against
 * the exponential's Taylor series); a wrong weight leaves an error of order z or z^2. */
static void test_sampled_step_reads_the_motor_to_its_order(void)
{
    const double theta[3] = {0.25, 0.5, 0.75};
    const double coeff[3] = {11.0 / 2048.0, 5.0 / 384.0, 27.0 / 2048.0};
    plant.ground_enabled = 0;
    const double tau = vehicle.motor_time_constant, h = 0.002, z = h / tau;
    for (int j = 0; j < 3; j++) {
        sitl_state_t s, sample;
        memset(&s, 0, sizeof(s));
        s.quat[0] = 1.0;
        s.position[2] = 100.0;
        double cmd[SITL_MAX_ROTORS];
        for (int i = 0; i < SITL_MAX_ROTORS; i++) {
            s.rotor_speed[i] = vehicle.rotor_speed_min;
            cmd[i] = vehicle.rotor_speed_max;
        }
        const double drive = vehicle.rotor_speed_max - vehicle.rotor_speed_min;
        sitl_plant_prepared_t prepared;
        sitl_plant_prepare(&plant, cmd, &prepared);
        sitl_plant_step_prepared_sampled(&plant, &prepared, &s, h, theta[j], &sample);
        const double exact = vehicle.rotor_speed_max - drive * exp(-theta[j] * z);
        const double expected = coeff[j] * z * z * z * z * drive;
        for (int i = 0; i < vehicle.rotor_count; i++) {
            const double error = fabs(sample.rotor_speed[i] - exact);
            TEST_ASSERT_TRUE(error > 0.9 * expected && error < 1.1 * expected);
        }
    }
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_free_fall_is_exact);
    RUN_TEST(test_hover_speeds_hold_the_vehicle);
    RUN_TEST(test_plus_layout_torque_signs);
    RUN_TEST(test_x_layout_geometry);
    RUN_TEST(test_motor_first_order_lag);
    RUN_TEST(test_torque_free_rotation_conserves_energy_and_momentum);
    RUN_TEST(test_ground_holds_and_releases);
    RUN_TEST(test_step_size_independence);
    RUN_TEST(test_prepared_steps_match_plain_steps);
    RUN_TEST(test_physics_rate_rule);
    RUN_TEST(test_physics_rate_rule_bounds_the_motor_error);
    RUN_TEST(test_sampled_step_ends_like_the_plain_step);
    RUN_TEST(test_sampled_step_reads_the_motor_to_its_order);
    return UNITY_END();
}
