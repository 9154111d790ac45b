/*
 * The integration loop: ISR callbacks hand samples to the main loop through
 * one-slot mailboxes; the loop pushes them into the filter in time order,
 * runs a rate controller on the bias-corrected gyro, and allocates the wanted
 * torques to rotor speeds with the identified coefficients.
 */
#include "port_example.h"

#include <string.h>

#define PORT_TWO_PI 6.28318530717958647692f

/* Hummingbird-class quad (docs/sitl.md, vehicles): nominal coefficients the allocation starts from. */
#define PORT_ARM_M 0.17f
#define PORT_THRUST_COEFF 5.57e-6f
#define PORT_DRAG_COEFF 1.36e-7f
#define PORT_JXX 3.65e-3f
#define PORT_JYY 3.68e-3f
#define PORT_JZZ 7.03e-3f

/* Rate-loop gain [1/s]: angular acceleration per rad/s of rate error. */
#define PORT_RATE_GAIN 40.0f

/* A single-producer (ISR) / single-consumer (loop) slot. `sequence` is odd while
 * the ISR writes, so the loop can detect a torn read and retry. */
typedef struct {
    volatile uint32_t sequence;
    uint64_t time_us;
    float value[PORT_ROTORS];
} port_mailbox_t;

static propid_filter_t filter;          /* static: the filter never allocates */
static propid_config_t vehicle;
static port_allocation_t allocation;
static port_mailbox_t esc_mailbox;
static port_mailbox_t gyro_mailbox;
static uint32_t esc_taken;
static uint32_t gyro_taken;
static uint32_t dropped;                /* samples overwritten before the loop took them */
static uint32_t rejected;               /* samples the filter refused */
static uint64_t next_allocation_us;
static float setpoint_rate[3];
static float setpoint_thrust;

void port_vehicle_config(propid_config_t *config)
{
    propid_config_default(config);
    /* Plus frame, rotor 0 on +x, counter-clockwise; yaw signs alternate. */
    (void)propid_config_set_symmetric(config, PORT_ROTORS, PORT_ARM_M, 0.0f, 1.0f,
                                      PORT_THRUST_COEFF, PORT_DRAG_COEFF);
    propid_config_set_inertia_diag(config, PORT_JXX, PORT_JYY, PORT_JZZ);
    config->gyro_sample_rate_hz = PORT_GYRO_RATE_HZ;
    config->max_rotor_speed = 1.5f * PORT_MAX_ROTOR_SPEED;
}

propid_status_t port_init(void)
{
    port_vehicle_config(&vehicle);
    const propid_status_t status = propid_init(&filter, &vehicle);
    if (status != PROPID_OK) {
        return status;
    }
    if (port_allocation_build(&allocation, &vehicle, NULL) != 0) {
        return PROPID_ERR_CONFIG;
    }
    memset(&esc_mailbox, 0, sizeof(esc_mailbox));
    memset(&gyro_mailbox, 0, sizeof(gyro_mailbox));
    esc_taken = gyro_taken = dropped = rejected = 0u;
    next_allocation_us = 0u;
    return PROPID_OK;
}

static void mailbox_put(port_mailbox_t *box, const uint32_t *taken, uint64_t time_us,
                        const float *value, uint8_t count)
{
    if (box->sequence != *taken) {
        ++dropped; /* the loop did not take the previous sample in time */
    }
    box->sequence++;
    box->time_us = time_us;
    for (uint8_t i = 0; i < count; ++i) {
        box->value[i] = value[i];
    }
    box->sequence++;
}

/* 1 if a new sample was copied out. On an MCU the ISR cannot interleave with
 * itself, so one retry after a torn read is enough in practice; bound it anyway. */
static int mailbox_take(port_mailbox_t *box, uint32_t *taken, uint64_t *time_us, float *value,
                        uint8_t count)
{
    for (uint8_t attempt = 0; attempt < 4u; ++attempt) {
        const uint32_t before = box->sequence;
        if (before == *taken || (before & 1u) != 0u) {
            return 0;
        }
        *time_us = box->time_us;
        for (uint8_t i = 0; i < count; ++i) {
            value[i] = box->value[i];
        }
        /* `sequence` is volatile: the ISR may have moved it since `before`. */
        // cppcheck-suppress knownConditionTrueFalse
        if (box->sequence == before) {
            *taken = before;
            return 1;
        }
    }
    return 0;
}

void port_on_esc_telemetry(uint64_t time_us, const uint32_t erpm[PORT_ROTORS])
{
    /* Convert at the boundary: electrical RPM -> mechanical rad/s. */
    const float erpm_to_rad_s = PORT_TWO_PI / (60.0f * (float)PORT_MOTOR_POLE_PAIRS);
    float rotor_speed[PORT_ROTORS];
    for (uint8_t i = 0; i < PORT_ROTORS; ++i) {
        rotor_speed[i] = (float)erpm[i] * erpm_to_rad_s;
    }
    mailbox_put(&esc_mailbox, &esc_taken, time_us, rotor_speed, PORT_ROTORS);
}

void port_on_gyro_sample(uint64_t time_us, const float gyro_rad_s[3])
{
    mailbox_put(&gyro_mailbox, &gyro_taken, time_us, gyro_rad_s, 3u);
}

void port_set_setpoint(const float body_rate[3], float thrust_n)
{
    for (uint8_t a = 0; a < 3u; ++a) {
        setpoint_rate[a] = body_rate[a];
    }
    setpoint_thrust = thrust_n;
}

int port_loop_step(float rotor_speed_cmd[PORT_ROTORS])
{
    uint64_t time_us;
    float sample[PORT_ROTORS];

    /* Rotor speeds first: the gyro sample is predicted with the latest ones. */
    if (mailbox_take(&esc_mailbox, &esc_taken, &time_us, sample, PORT_ROTORS)) {
        if (propid_push_rotor_speeds(&filter, time_us, sample, PORT_ROTORS) < 0) {
            ++rejected;
        }
    }
    if (!mailbox_take(&gyro_mailbox, &gyro_taken, &time_us, sample, 3u)) {
        return 0;
    }
    const propid_status_t status = propid_push_gyro(&filter, time_us, sample);
    if (status == PROPID_ERR_TIME_JUMP) {
        /* The loop stalled (e.g. flash write): re-anchor and carry on. */
        (void)propid_resync(&filter, time_us);
        ++rejected;
    } else if (status < 0) {
        ++rejected;
    }

    propid_estimate_t estimate;
    (void)propid_get_estimate(&filter, &estimate);

    /* Re-read the coefficients at a slow rate: rebuilding inverts a 4x4. */
    if (time_us >= next_allocation_us) {
        (void)port_allocation_build(&allocation, &vehicle, &estimate);
        next_allocation_us = time_us + PORT_ALLOCATION_PERIOD_US;
    }

    /* Rate loop on the bias-corrected gyro: tau = J * gain * (rate_sp - rate). */
    const float inertia_diag[3] = {vehicle.inertia[0][0], vehicle.inertia[1][1],
                                   vehicle.inertia[2][2]};
    float wrench[4];
    wrench[0] = setpoint_thrust;
    for (uint8_t a = 0; a < 3u; ++a) {
        const float rate = sample[a] - estimate.gyro_bias[a];
        wrench[1u + a] = inertia_diag[a] * PORT_RATE_GAIN * (setpoint_rate[a] - rate);
    }
    port_allocation_apply(&allocation, wrench, PORT_MAX_ROTOR_SPEED, rotor_speed_cmd);
    return 1;
}

const propid_config_t *port_vehicle(void)
{
    return &vehicle;
}

const propid_filter_t *port_filter(void)
{
    return &filter;
}

const port_allocation_t *port_allocation(void)
{
    return &allocation;
}

uint32_t port_dropped_samples(void)
{
    return dropped;
}

uint32_t port_rejected_samples(void)
{
    return rejected;
}
