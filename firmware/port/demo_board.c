/*
 * Demo "board" for the port example: it stands in for the hardware so the
 * integration loop can run unchanged on the host and on Cortex-M4F under QEMU.
 * A small rotational model of the quad (true kf/km differ from the nominal
 * ones the example is configured with, a gyro bias, gyro noise, motor lag)
 * produces the gyro interrupt at 1 kHz and ESC telemetry at 500 Hz; the
 * rate setpoint is a multi-sine that excites roll, pitch, yaw and thrust.
 *
 * Exit status 0 when the loop ran without rejected or dropped samples and the
 * filter identified every rotor's kf and km to within 10 % of the truth.
 */
#include <math.h>
#include <stdint.h>

#include "port_example.h"

#ifdef PROPID_PORT_QEMU
#include "semihosting.h"
#include "stack_watermark.h"
static void board_print(const char *text)
{
    propid_qemu_puts(text);
}
#else
#include <stdio.h>
static void board_print(const char *text)
{
    (void)fputs(text, stdout);
}
#endif

#define DEMO_SECONDS 12u
#define DEMO_TICK_US 1000u       /* gyro interrupt period */
#define DEMO_ESC_EVERY_TICKS 2u  /* ESC telemetry at 500 Hz */
#define DEMO_SUBSTEPS 4u         /* physics steps per tick */
#define DEMO_MOTOR_TAU_S 0.02f
#define DEMO_GYRO_NOISE 0.01f    /* uniform +-, rad/s */
#define DEMO_TOLERANCE 0.10f     /* relative error accepted at the end */
#define DEMO_TWO_PI 6.28318530717958647692f

/* Truth: how far each propeller is from its nominal coefficients. */
static const float true_thrust_ratio[PORT_ROTORS] = {1.00f, 0.85f, 1.10f, 0.95f};
static const float true_drag_ratio[PORT_ROTORS] = {1.00f, 1.15f, 0.90f, 1.05f};
static const float true_gyro_bias[3] = {0.010f, -0.020f, 0.015f};

static uint32_t noise_state = 0x2545F491u;

static float noise_uniform(void)
{
    /* xorshift32: deterministic, float-only, no libc */
    noise_state ^= noise_state << 13;
    noise_state ^= noise_state >> 17;
    noise_state ^= noise_state << 5;
    return (float)(noise_state >> 8) * (2.0f / 16777216.0f) - 1.0f;
}

/* ---- text output without printf (no double, no heap) -------------------- */
static void print_int(int32_t value)
{
    char text[12];
    char *end = &text[sizeof text - 1u];
    *end = '\0';
    uint32_t magnitude = value < 0 ? (uint32_t)(-(value + 1)) + 1u : (uint32_t)value;
    do {
        *--end = (char)('0' + (magnitude % 10u));
        magnitude /= 10u;
    } while (magnitude != 0u);
    if (value < 0) {
        *--end = '-';
    }
    board_print(end);
}

static void print_fixed3(float value)
{
    if (!isfinite(value)) {
        board_print("nan");
        return;
    }
    const int32_t milli = (int32_t)lroundf(value * 1000.0f);
    const int32_t whole = milli / 1000;
    int32_t frac = milli % 1000;
    if (milli < 0) {
        board_print("-");
        frac = -frac;
    }
    print_int(whole < 0 ? -whole : whole);
    board_print(".");
    if (frac < 100) {
        board_print("0");
    }
    if (frac < 10) {
        board_print("0");
    }
    print_int(frac);
}

/* ---- the vehicle the board pretends to be ------------------------------- */
typedef struct {
    float body_rate[3];
    float rotor_speed[PORT_ROTORS];
    float thrust_coeff[PORT_ROTORS];
    float drag_coeff[PORT_ROTORS];
} demo_vehicle_t;

static void vehicle_step(demo_vehicle_t *v, const propid_config_t *config,
                         const float rotor_speed_cmd[PORT_ROTORS], float dt)
{
    float torque[3] = {0.0f, 0.0f, 0.0f};
    for (uint8_t i = 0; i < PORT_ROTORS; ++i) {
        v->rotor_speed[i] += (rotor_speed_cmd[i] - v->rotor_speed[i]) * (dt / DEMO_MOTOR_TAU_S);
        const float speed_sq = v->rotor_speed[i] * v->rotor_speed[i];
        const float thrust = v->thrust_coeff[i] * speed_sq;
        torque[0] += config->rotor[i].position_m[1] * thrust;
        torque[1] -= config->rotor[i].position_m[0] * thrust;
        torque[2] += config->rotor[i].yaw_sign * v->drag_coeff[i] * speed_sq;
    }
    const float jx = config->inertia[0][0], jy = config->inertia[1][1], jz = config->inertia[2][2];
    const float *w = v->body_rate;
    const float gyroscopic[3] = {w[1] * w[2] * (jz - jy), w[2] * w[0] * (jx - jz),
                                 w[0] * w[1] * (jy - jx)};
    v->body_rate[0] += dt * (torque[0] - gyroscopic[0]) / jx;
    v->body_rate[1] += dt * (torque[1] - gyroscopic[1]) / jy;
    v->body_rate[2] += dt * (torque[2] - gyroscopic[2]) / jz;
}

static int within(float estimate, float truth)
{
    return isfinite(estimate) && fabsf(estimate / truth - 1.0f) < DEMO_TOLERANCE;
}

int main(void)
{
    if (port_init() != PROPID_OK) {
        board_print("port example: propid_init failed\n");
        return 1;
    }
    const propid_config_t *config = port_vehicle();

    demo_vehicle_t vehicle = {{0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 0.0f, 0.0f}, {0}, {0}};
    float hover_thrust = 0.0f;
    for (uint8_t i = 0; i < PORT_ROTORS; ++i) {
        vehicle.thrust_coeff[i] = true_thrust_ratio[i] * config->rotor[i].thrust_coeff_nominal;
        vehicle.drag_coeff[i] = true_drag_ratio[i] * config->rotor[i].drag_coeff_nominal;
        hover_thrust += vehicle.thrust_coeff[i] * 470.0f * 470.0f;
        vehicle.rotor_speed[i] = 470.0f;
    }

    float rotor_speed_cmd[PORT_ROTORS] = {470.0f, 470.0f, 470.0f, 470.0f};
    const uint32_t ticks = DEMO_SECONDS * (1000000u / DEMO_TICK_US);
    const float dt = 1.0e-6f * (float)DEMO_TICK_US / (float)DEMO_SUBSTEPS;
    uint32_t loop_steps = 0u;
    for (uint32_t tick = 1u; tick <= ticks; ++tick) {
        const uint64_t now_us = (uint64_t)tick * DEMO_TICK_US;
        const float t = 1.0e-6f * (float)now_us;

        /* Pilot: a multi-sine on every axis and on thrust. */
        const float rate_sp[3] = {2.0f * sinf(DEMO_TWO_PI * 0.7f * t),
                                  2.0f * sinf(DEMO_TWO_PI * 0.9f * t + 1.0f),
                                  3.0f * sinf(DEMO_TWO_PI * 0.5f * t + 2.0f)};
        port_set_setpoint(rate_sp, hover_thrust * (1.0f + 0.25f * sinf(DEMO_TWO_PI * 0.3f * t)));

        for (uint8_t s = 0; s < DEMO_SUBSTEPS; ++s) {
            vehicle_step(&vehicle, config, rotor_speed_cmd, dt);
        }

        /* "Interrupts" of this tick. */
        if (tick % DEMO_ESC_EVERY_TICKS == 1u) { /* telemetry arrives first on odd ticks */
            const float rad_s_to_erpm = 60.0f * (float)PORT_MOTOR_POLE_PAIRS / DEMO_TWO_PI;
            uint32_t erpm[PORT_ROTORS];
            for (uint8_t i = 0; i < PORT_ROTORS; ++i) {
                erpm[i] = (uint32_t)lroundf(vehicle.rotor_speed[i] * rad_s_to_erpm);
            }
            port_on_esc_telemetry(now_us, erpm);
        }
        float gyro[3];
        for (uint8_t a = 0; a < 3u; ++a) {
            gyro[a] = vehicle.body_rate[a] + true_gyro_bias[a] + DEMO_GYRO_NOISE * noise_uniform();
        }
        port_on_gyro_sample(now_us, gyro);

        /* Main loop: runs once per tick here; on hardware as fast as it can. */
        loop_steps += (uint32_t)port_loop_step(rotor_speed_cmd);
    }

    propid_estimate_t estimate;
    propid_counters_t counters;
    (void)propid_get_estimate(port_filter(), &estimate);
    (void)propid_get_counters(port_filter(), &counters);
    const port_allocation_t *allocation = port_allocation();

    int identified = 1;
    board_print("propid port example: ");
    print_int((int32_t)DEMO_SECONDS);
    board_print(" s, gyro 1 kHz, ESC telemetry 500 Hz\n");
    board_print("rotor  kf/nom true  est   std    km/nom true  est   std    allocation\n");
    for (uint8_t i = 0; i < PORT_ROTORS; ++i) {
        const float kf_nom = config->rotor[i].thrust_coeff_nominal;
        const float km_nom = config->rotor[i].drag_coeff_nominal;
        board_print("  ");
        print_int(i);
        board_print("         ");
        print_fixed3(true_thrust_ratio[i]);
        board_print(" ");
        print_fixed3(estimate.thrust_coeff[i] / kf_nom);
        board_print(" ");
        print_fixed3(estimate.thrust_coeff_std[i] / kf_nom);
        board_print("         ");
        print_fixed3(true_drag_ratio[i]);
        board_print(" ");
        print_fixed3(estimate.drag_coeff[i] / km_nom);
        board_print(" ");
        print_fixed3(estimate.drag_coeff_std[i] / km_nom);
        board_print((((uint32_t)allocation->estimated_thrust_mask >> i) & 1u) ? "  estimated kf" : "  nominal kf");
        board_print((((uint32_t)allocation->estimated_drag_mask >> i) & 1u) ? ", estimated km\n" : ", nominal km\n");
        identified &= within(estimate.thrust_coeff[i], vehicle.thrust_coeff[i]);
        identified &= within(estimate.drag_coeff[i], vehicle.drag_coeff[i]);
    }
    board_print("gyro bias true/est [mrad/s]:");
    for (uint8_t a = 0; a < 3u; ++a) {
        board_print(" ");
        print_int((int32_t)lroundf(1000.0f * true_gyro_bias[a]));
        board_print("/");
        print_int((int32_t)lroundf(1000.0f * estimate.gyro_bias[a]));
    }
    board_print("\nloop steps ");
    print_int((int32_t)loop_steps);
    board_print(", gyro accepted ");
    print_int((int32_t)counters.gyro_accepted);
    board_print(", rotor accepted ");
    print_int((int32_t)counters.rotor_accepted);
    board_print(", rejected ");
    print_int((int32_t)port_rejected_samples());
    board_print(", dropped ");
    print_int((int32_t)port_dropped_samples());
    board_print("\n");
#ifdef PROPID_PORT_QEMU
    board_print("stack used ");
    print_int((int32_t)propid_qemu_stack_used());
    board_print(" of ");
    print_int((int32_t)propid_qemu_stack_size());
    board_print(" bytes (painted-stack high-water mark)\n");
#endif
    const int clean = port_rejected_samples() == 0u && port_dropped_samples() == 0u &&
                      loop_steps == ticks;
    board_print(clean && identified ? "PASS\n" : "FAIL: rejected/dropped samples or kf/km off by > 10 %\n");
    return clean && identified ? 0 : 1;
}
