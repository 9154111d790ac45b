/*
 * The switchable effects: off = no change at all; each one on changes the
 * physics in the documented direction and by the documented amount.
 */
#include <math.h>
#include <string.h>

#include "effects.h"
#include "esc_telemetry.h"
#include "imu.h"
#include "plant.h"
#include "sitl_math.h"
#include "unity.h"

static sitl_vehicle_t vehicle;

void setUp(void)
{
    sitl_vehicle_preset("hummingbird-plus", &vehicle);
}

void tearDown(void)
{
}

static void make(sitl_plant_t *p, const char *effect)
{
    sitl_effects_t fx;
    char err[512];
    sitl_effects_clear(&fx);
    if (effect != NULL) {
        TEST_ASSERT_EQUAL_INT_MESSAGE(0, sitl_effects_parse(&fx, effect, err, 512), err);
    }
    TEST_ASSERT_EQUAL_INT_MESSAGE(0, sitl_plant_init(p, &vehicle, NULL, NULL, &fx, err, 512), err);
}

/* A generic moving state: velocity, body rates, unequal rotor speeds, 1 m up. */
static void moving_state(const sitl_plant_t *p, sitl_state_t *s)
{
    double pos[3] = {0.0, 0.0, 1.0};
    sitl_plant_hover_state(p, pos, 0.2, s);
    sitl_vec3_set(s->velocity, 2.0, -1.0, 0.5);
    sitl_vec3_set(s->body_rate, 0.7, -0.4, 1.1);
    s->rotor_speed[0] *= 1.05;
    s->rotor_speed[2] *= 0.97;
}

static void loads_of(const sitl_plant_t *p, const sitl_state_t *s, const double *cmd,
                     sitl_loads_t *ld)
{
    sitl_state_derivative_t d;
    sitl_plant_derivative(p, s, cmd, &d, ld);
}

static void test_parse_names_and_strengths(void)
{
    sitl_effects_t fx;
    char err[512];
    sitl_effects_clear(&fx);
    TEST_ASSERT_EQUAL_INT(0, sitl_effects_parse(&fx, "rotor_drag", err, 512));
    TEST_ASSERT_EQUAL_DOUBLE(1.0, sitl_effect_strength(&fx, SITL_EFFECT_ROTOR_DRAG));
    TEST_ASSERT_EQUAL_INT(0, sitl_effects_parse(&fx, "esc_delay=0.05", err, 512));
    TEST_ASSERT_EQUAL_DOUBLE(0.05, sitl_effect_strength(&fx, SITL_EFFECT_ESC_DELAY));
    TEST_ASSERT_EQUAL_DOUBLE(0.0, sitl_effect_strength(&fx, SITL_EFFECT_GYRO_SCALE));
    TEST_ASSERT_EQUAL_INT(-1, sitl_effects_parse(&fx, "warp_drive", err, 512));
    TEST_ASSERT_NOT_NULL(strstr(err, "unknown effect"));
    TEST_ASSERT_EQUAL_INT(-1, sitl_effects_parse(&fx, "rotor_drag=abc", err, 512));
    for (int i = 0; i < SITL_EFFECT_COUNT; i++) {
        const sitl_effect_info_t *info = sitl_effect_info((sitl_effect_id_t)i);
        TEST_ASSERT_NOT_NULL(info);
        TEST_ASSERT_EQUAL_INT(0, sitl_effects_parse(&fx, info->name, err, 512));
    }
    char desc[512];
    sitl_effects_describe(&fx, desc, 512);
    TEST_ASSERT_NOT_NULL(strstr(desc, "aero_damping=1"));
    TEST_ASSERT_EQUAL_INT(0, sitl_effects_parse(&fx, "none", err, 512));
    sitl_effects_describe(&fx, desc, 512);
    TEST_ASSERT_EQUAL_STRING("none", desc);
}

static void test_all_off_is_the_ideal_model(void)
{
    sitl_plant_t p;
    make(&p, NULL);
    sitl_state_t s;
    moving_state(&p, &s);
    sitl_loads_t ld;
    loads_of(&p, &s, s.rotor_speed, &ld);
    double tz = 0.0, fz = 0.0;
    for (int i = 0; i < 4; i++) {
        double u = s.rotor_speed[i] * s.rotor_speed[i];
        fz += vehicle.rotor[i].thrust_coeff * u;
        tz += vehicle.rotor[i].yaw_sign * vehicle.rotor[i].drag_coeff * u;
    }
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, fz, ld.force_body[2]);
    TEST_ASSERT_EQUAL_DOUBLE(0.0, ld.force_body[0]);
    TEST_ASSERT_DOUBLE_WITHIN(1e-15, tz, ld.torque_body[2]);
    TEST_ASSERT_EQUAL_DOUBLE(0.0, sitl_vec3_norm(ld.effect_torque_body));
}

static void test_rotor_inertia_yaw_reaction_during_spin_up(void)
{
    sitl_plant_t ideal, p;
    make(&ideal, NULL);
    make(&p, "rotor_inertia");
    sitl_state_t s;
    double pos[3] = {0.0, 0.0, 1.0};
    sitl_plant_hover_state(&p, pos, 0.0, &s);
    double cmd[SITL_MAX_ROTORS];
    memcpy(cmd, s.rotor_speed, sizeof(cmd));
    cmd[0] += 200.0; /* spin up rotor 1 (yaw_sign +1) */
    sitl_loads_t a, b;
    loads_of(&ideal, &s, cmd, &a);
    loads_of(&p, &s, cmd, &b);
    double accel = 200.0 / vehicle.motor_time_constant;
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, accel, b.rotor_accel[0]);
    /* tau_z = +yaw_sign * J_r * dOmega/dt: same sign as that rotor's drag torque. */
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, vehicle.rotor_inertia * accel, b.torque_body[2] - a.torque_body[2]);
    TEST_ASSERT_DOUBLE_WITHIN(1e-15, 0.0, b.torque_body[0] - a.torque_body[0]);
    /* Steady speed: no reaction. */
    loads_of(&p, &s, s.rotor_speed, &b);
    loads_of(&ideal, &s, s.rotor_speed, &a);
    TEST_ASSERT_DOUBLE_WITHIN(1e-15, 0.0, b.torque_body[2] - a.torque_body[2]);
}

static void test_rotor_gyroscopic_torque(void)
{
    sitl_plant_t ideal, p;
    make(&ideal, NULL);
    make(&p, "rotor_gyroscopic=2");
    sitl_state_t s;
    double pos[3] = {0.0, 0.0, 1.0};
    sitl_plant_hover_state(&p, pos, 0.0, &s);
    s.rotor_speed[0] += 100.0; /* net momentum: rotor 1 spins about -z (yaw_sign +) */
    sitl_vec3_set(s.body_rate, 1.0, 0.0, 0.0);
    sitl_loads_t a, b;
    loads_of(&ideal, &s, s.rotor_speed, &a);
    loads_of(&p, &s, s.rotor_speed, &b);
    double hz = 0.0;
    for (int i = 0; i < 4; i++) {
        hz -= 2.0 * vehicle.rotor[i].yaw_sign * vehicle.rotor_inertia * s.rotor_speed[i];
    }
    /* tau = -w x h = -(1,0,0) x (0,0,hz) = (0, hz, 0) */
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, hz, b.torque_body[1] - a.torque_body[1]);
    TEST_ASSERT_TRUE(fabs(hz) > 0.0);
}

static void test_rotor_drag_opposes_velocity_and_flaps_nose_up(void)
{
    sitl_plant_t p;
    make(&p, "rotor_drag");
    sitl_state_t s;
    double pos[3] = {0.0, 0.0, 1.0};
    sitl_plant_hover_state(&p, pos, 0.0, &s);
    sitl_vec3_set(s.velocity, 3.0, 0.0, 0.0);
    sitl_loads_t ld;
    loads_of(&p, &s, s.rotor_speed, &ld);
    double sum_w = 0.0;
    for (int i = 0; i < 4; i++) {
        sum_w += s.rotor_speed[i];
    }
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, -vehicle.rotor_drag_coeff * sum_w * 3.0, ld.force_body[0]);
    TEST_ASSERT_TRUE(ld.effect_torque_body[1] < 0.0); /* nose up */
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, -vehicle.flapping_coeff * sum_w * 3.0,
                              ld.effect_torque_body[1]);
    /* Climbing: inflow drag reduces the net vertical force. */
    sitl_loads_t climb, hover;
    sitl_vec3_set(s.velocity, 0.0, 0.0, 2.0);
    loads_of(&p, &s, s.rotor_speed, &climb);
    sitl_vec3_set(s.velocity, 0.0, 0.0, 0.0);
    loads_of(&p, &s, s.rotor_speed, &hover);
    TEST_ASSERT_TRUE(climb.force_body[2] < hover.force_body[2]);
}

static void test_translational_lift_grows_with_airspeed(void)
{
    sitl_plant_t p;
    make(&p, "translational_lift");
    sitl_state_t s;
    double pos[3] = {0.0, 0.0, 1.0};
    sitl_plant_hover_state(&p, pos, 0.0, &s);
    sitl_loads_t still, fast;
    loads_of(&p, &s, s.rotor_speed, &still);
    sitl_vec3_set(s.velocity, 0.0, 4.0, 0.0);
    loads_of(&p, &s, s.rotor_speed, &fast);
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, 4.0 * 16.0 * vehicle.translational_lift_coeff,
                              fast.force_body[2] - still.force_body[2]);
}

static void test_ground_effect_near_ground_only(void)
{
    sitl_plant_t ideal, p;
    make(&ideal, NULL);
    make(&p, "ground_effect");
    sitl_state_t s;
    double low[3] = {0.0, 0.0, vehicle.rotor_radius}; /* h = R: 1/(1 - 1/16) */
    sitl_plant_hover_state(&p, low, 0.0, &s);
    sitl_loads_t a, b;
    loads_of(&ideal, &s, s.rotor_speed, &a);
    loads_of(&p, &s, s.rotor_speed, &b);
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, 16.0 / 15.0, b.thrust[0] / a.thrust[0]);
    s.position[2] = 2.0;
    loads_of(&ideal, &s, s.rotor_speed, &a);
    loads_of(&p, &s, s.rotor_speed, &b);
    TEST_ASSERT_TRUE(b.thrust[0] / a.thrust[0] < 1.001);
}

static void test_com_offset_and_inertia_error_change_the_body(void)
{
    sitl_plant_t ideal, p;
    make(&ideal, NULL);
    make(&p, "com_offset=0.1");
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, vehicle.rotor[0].position[0] - 0.1 * 0.17 * 0.6,
                              p.rotor_position[0][0]);
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, 0.1 * 0.17 * 0.5, p.rotor_position[0][2]);
    double ws[4];
    TEST_ASSERT_EQUAL_INT(0, sitl_plant_hover_speeds(&p, ws));
    TEST_ASSERT_TRUE(fabs(ws[0] - ws[2]) > 1.0); /* the nominal allocation would now tilt */
    make(&p, "inertia_error=0.2");
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, 1.2 * vehicle.inertia[2][2], p.inertia[2][2]);
    sitl_state_t s;
    moving_state(&ideal, &s);
    memset(s.body_rate, 0, sizeof(s.body_rate)); /* w x Jw scales differently */
    sitl_state_derivative_t da, db;
    sitl_plant_derivative(&ideal, &s, s.rotor_speed, &da, NULL);
    sitl_plant_derivative(&p, &s, s.rotor_speed, &db, NULL);
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, da.body_rate[2] / 1.2, db.body_rate[2]);
}

static void test_thrust_nonlinearity_equal_at_hover_stronger_above(void)
{
    sitl_plant_t ideal, p;
    make(&ideal, NULL);
    make(&p, "thrust_nonlinearity=0.2");
    sitl_state_t s;
    double pos[3] = {0.0, 0.0, 1.0};
    sitl_plant_hover_state(&ideal, pos, 0.0, &s);
    sitl_loads_t a, b;
    loads_of(&ideal, &s, s.rotor_speed, &a);
    loads_of(&p, &s, s.rotor_speed, &b);
    TEST_ASSERT_DOUBLE_WITHIN(1e-9 * a.thrust[0], a.thrust[0], b.thrust[0]);
    for (int i = 0; i < 4; i++) {
        s.rotor_speed[i] *= 1.3;
    }
    loads_of(&ideal, &s, s.rotor_speed, &a);
    loads_of(&p, &s, s.rotor_speed, &b);
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, pow(1.3, 0.2), b.thrust[0] / a.thrust[0]);
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, pow(1.3, 0.2), b.drag_torque[0] / a.drag_torque[0]);
}

static void test_aero_damping_opposes_rotation(void)
{
    sitl_plant_t ideal, p;
    make(&ideal, NULL);
    make(&p, "aero_damping");
    sitl_state_t s;
    double pos[3] = {0.0, 0.0, 1.0};
    sitl_plant_hover_state(&p, pos, 0.0, &s);
    for (int axis = 0; axis < 3; axis++) {
        memset(s.body_rate, 0, sizeof(s.body_rate));
        s.body_rate[axis] = 2.0;
        sitl_loads_t a, b;
        loads_of(&ideal, &s, s.rotor_speed, &a);
        loads_of(&p, &s, s.rotor_speed, &b);
        TEST_ASSERT_TRUE(b.torque_body[axis] - a.torque_body[axis] < 0.0);
    }
}

static void test_gyro_scale_and_esc_delay_reach_the_sensors(void)
{
    sitl_effects_t fx;
    char err[256];
    sitl_effects_clear(&fx);
    TEST_ASSERT_EQUAL_INT(0, sitl_effects_parse(&fx, "gyro_scale=0.05", err, 256));
    TEST_ASSERT_EQUAL_INT(0, sitl_effects_parse(&fx, "esc_delay=0.03", err, 256));
    sitl_imu_params_t ip;
    sitl_imu_paper_params(&ip);
    ip.gyro.noise_density = 0.0;
    ip.gyro.bias_max = 0.0;
    ip.accel.noise_density = 0.0;
    ip.accel.bias_max = 0.0;
    sitl_imu_t imu;
    sitl_imu_init(&imu, &ip, 1, 1, &fx);
    double w[3] = {1.0, 0.0, 0.0}, f[3] = {0.0, 0.0, 9.81}, g[3], acc[3];
    sitl_imu_sample(&imu, w, f, 0.002, g, acc);
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, 1.05, g[0]);
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, 0.025, g[1]);

    sitl_esc_params_t ep;
    sitl_esc_paper_params(&ep, 500.0);
    sitl_esc_telemetry_t esc;
    TEST_ASSERT_EQUAL_INT(0, sitl_esc_init(&esc, &ep, 1, sitl_effects_esc_extra_delay(&fx),
                                           2000.0, 1));
    for (int k = 0; k <= 200; k++) {
        double t = k * 0.0005, speed = 1000.0 + 1000.0 * t; /* ramp 1000 rad/s per s */
        sitl_esc_record(&esc, t, &speed);
    }
    double out;
    TEST_ASSERT_EQUAL_INT(1, sitl_esc_report(&esc, 0.1, &out));
    TEST_ASSERT_DOUBLE_WITHIN(1e-6, 1000.0 + 1000.0 * (0.1 - 0.03), out);
    sitl_esc_free(&esc);
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_parse_names_and_strengths);
    RUN_TEST(test_all_off_is_the_ideal_model);
    RUN_TEST(test_rotor_inertia_yaw_reaction_during_spin_up);
    RUN_TEST(test_rotor_gyroscopic_torque);
    RUN_TEST(test_rotor_drag_opposes_velocity_and_flaps_nose_up);
    RUN_TEST(test_translational_lift_grows_with_airspeed);
    RUN_TEST(test_ground_effect_near_ground_only);
    RUN_TEST(test_com_offset_and_inertia_error_change_the_body);
    RUN_TEST(test_thrust_nonlinearity_equal_at_hover_stronger_above);
    RUN_TEST(test_aero_damping_opposes_rotation);
    RUN_TEST(test_gyro_scale_and_esc_delay_reach_the_sensors);
    return UNITY_END();
}
