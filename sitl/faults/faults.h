/* Fault injection between the simulated sensors and the filter (docs/sitl.md,
 * "Faults"): what a flight controller sees from broken ESC telemetry, a
 * misbehaving gyro or clock, and a rotor that loses thrust. Switchable per
 * class with a rate (`--fault NAME=RATE`), seeded from the run's seed. */
#ifndef SITL_FAULTS_H
#define SITL_FAULTS_H

#include <stdint.h>

#include "rng.h"
#include "vehicle.h"

typedef enum {
    SITL_FAULT_ESC_DROPOUT,      /* ESC sample lost */
    SITL_FAULT_ESC_SPIKE,        /* one rotor's speed decoded as garbage (CRC-failed frame) */
    SITL_FAULT_ESC_STUCK,        /* telemetry repeats the same speeds for a burst */
    SITL_FAULT_ESC_STALE,        /* telemetry stops for a burst (ESC link down) */
    SITL_FAULT_GYRO_SPIKE,       /* one axis far off for one sample */
    SITL_FAULT_GYRO_SATURATION,  /* one axis clipped to (beyond) full scale */
    SITL_FAULT_GYRO_STUCK,       /* one axis frozen for a burst */
    SITL_FAULT_TIME_JITTER,      /* timestamps off by a random amount (RATE = std in us) */
    SITL_FAULT_TIME_REPEAT,      /* a sample carries the previous stamp */
    SITL_FAULT_TIME_BACKWARD,    /* a sample stamped before the previous one */
    SITL_FAULT_TIME_JUMP,        /* the clock jumps forward (both streams from then on) */
    SITL_FAULT_ROTOR_LOSS,       /* rotor 0 loses 30 % of its thrust at t = RATE [s] */
    SITL_FAULT_COUNT
} sitl_fault_class_t;

typedef struct {
    double rate[SITL_FAULT_COUNT];      /* per sample of its stream (jitter: std [us]; rotor_loss: time [s]) */
    int enabled;                        /* any class on */
} sitl_fault_config_t;

typedef struct {
    sitl_fault_config_t config;
    sitl_rng_t rng;
    long injected[SITL_FAULT_COUNT];    /* events per class */
    int esc_stuck_left, esc_stale_left, gyro_stuck_left, gyro_stuck_axis;
    float esc_stuck_value[SITL_MAX_ROTORS];
    float gyro_stuck_value;
    uint64_t clock_offset_us;           /* accumulated forward jumps */
    uint64_t last_esc_us, last_gyro_us;
    int rotor_lost;
} sitl_faults_t;

/* "NAME=RATE" (or "none" = all off) into the configuration; 0 or -1 with a message. */
int sitl_faults_parse(sitl_fault_config_t *config, const char *text, char *err, int err_size);
/* The class names, `separator` between them (for --help). */
void sitl_faults_names(char *out, int out_size, const char *separator);
const char *sitl_fault_name(sitl_fault_class_t fault);

void sitl_faults_init(sitl_faults_t *faults, const sitl_fault_config_t *config, uint64_t seed);

/* An ESC sample about to be pushed: may change its stamp and speeds; returns 0
 * when the sample is lost. */
int sitl_faults_esc(sitl_faults_t *faults, uint64_t *time_us, float *speed, int rotor_count);
/* A gyro sample about to be pushed: may change its stamp and values; `range`
 * is the gyro's full scale (saturation clips just beyond it). */
void sitl_faults_gyro(sitl_faults_t *faults, uint64_t *time_us, float gyro[3], double range);
/* 1 once, at the first call with t >= the rotor-loss time: the caller then
 * multiplies rotor 0's true thrust coefficient by 0.7. */
int sitl_faults_rotor_loss_now(sitl_faults_t *faults, double t);
/* Whether sitl_faults_rotor_loss_now(t) would fire, without firing it. */
int sitl_faults_rotor_loss_due(const sitl_faults_t *faults, double t);

#endif
