/*
 * propid compile-time limits.
 *
 * Override any of these with -D on the compiler command line; they size every
 * array in propid_filter_t, so the filter never allocates.
 */
#ifndef PROPID_CONFIG_H
#define PROPID_CONFIG_H

/* The quad build (-DPROPID_QUAD_BUILD=1): at most 4 rotors and every optional
 * model term and sensor compiled out, unless switched on one by one below. It is
 * the small library an autopilot of a quadrotor links (docs/performance.md). */
#ifndef PROPID_QUAD_BUILD
#define PROPID_QUAD_BUILD 0
#endif
#if PROPID_QUAD_BUILD
#ifndef PROPID_MAX_ROTORS
#define PROPID_MAX_ROTORS 4
#endif
#define PROPID_DEFAULT_FEATURES 0
#else
#define PROPID_DEFAULT_FEATURES 1
#endif

/* Largest rotor count the filter is built for (quad 4, hexa 6, octo 8). */
#ifndef PROPID_MAX_ROTORS
#define PROPID_MAX_ROTORS 8
#endif

/* Optional model terms and sensors, each 1 (compiled in) or 0 (compiled out: a
 * configuration that asks for it is rejected by propid_config_check, its state
 * block and its derived data take no RAM, its code no flash). */
#ifndef PROPID_WITH_ACCEL               /* propid_push_accel(), accelerometer z bias, thrust-torque scale */
#define PROPID_WITH_ACCEL PROPID_DEFAULT_FEATURES
#endif
#ifndef PROPID_WITH_DISTURBANCE         /* disturbance-torque states */
#define PROPID_WITH_DISTURBANCE PROPID_DEFAULT_FEATURES
#endif
#ifndef PROPID_WITH_ROTOR_INERTIA       /* rotor yaw reaction and gyroscopic torque */
#define PROPID_WITH_ROTOR_INERTIA PROPID_DEFAULT_FEATURES
#endif
#ifndef PROPID_WITH_INPUT_NOISE         /* rotor-speed measurement error in the rate process noise */
#define PROPID_WITH_INPUT_NOISE PROPID_DEFAULT_FEATURES
#endif
#ifndef PROPID_WITH_INSTRUMENT          /* propid_push_motor_command(): the commands' first stage */
#define PROPID_WITH_INSTRUMENT PROPID_DEFAULT_FEATURES
#endif
#ifndef PROPID_WITH_GYRO_STUCK_CHECK    /* config.gyro_stuck_samples: bit-identical repeats not fused */
#define PROPID_WITH_GYRO_STUCK_CHECK PROPID_DEFAULT_FEATURES
#endif
#ifndef PROPID_WITH_AERO_DAMPING        /* a known aerodynamic rate damping -D omega in the rate dynamics */
#define PROPID_WITH_AERO_DAMPING PROPID_DEFAULT_FEATURES
#endif

/* 1: the step also has its general path, for any rotor count up to
 * PROPID_MAX_ROTORS, any inertia and the optional terms (the Jacobian's sparsity
 * lists and loops over them). 0 (the quad build with every optional term off):
 * only a 4-rotor vehicle whose inertia gives the step's fixed quad layout
 * (propid_internal.h: any diagonal inertia); propid_config_check rejects any
 * other ("rotor_count", "inertia"), and the lists, their loops and their work
 * rows take no RAM, flash or stack. */
#ifndef PROPID_GENERAL_VEHICLES
#define PROPID_GENERAL_VEHICLES (PROPID_DEFAULT_FEATURES || PROPID_WITH_ACCEL || PROPID_WITH_DISTURBANCE || \
                                 PROPID_WITH_ROTOR_INERTIA || PROPID_WITH_INPUT_NOISE || PROPID_WITH_INSTRUMENT || \
                                 PROPID_WITH_AERO_DAMPING || PROPID_WITH_GYRO_STUCK_CHECK)
#endif
#if !PROPID_GENERAL_VEHICLES && (PROPID_MAX_ROTORS != 4 || PROPID_WITH_ACCEL || PROPID_WITH_DISTURBANCE || \
                                 PROPID_WITH_ROTOR_INERTIA || PROPID_WITH_INPUT_NOISE || PROPID_WITH_INSTRUMENT || \
                                 PROPID_WITH_AERO_DAMPING || PROPID_WITH_GYRO_STUCK_CHECK)
#error "PROPID_GENERAL_VEHICLES 0 needs PROPID_MAX_ROTORS 4 and every optional model term off"
#endif

/* The size-lean quad build (-DPROPID_QUAD_BUILD=1 -DPROPID_SIZE_LEAN=1, CMake
 * target propid_quad_lean): the same filter, API, checks and results as the quad
 * build, with the step's kernels as loops instead of straight-line code (less
 * flash, more instructions per step; docs/performance.md compares the two).
 * Needs the quad build's fixed layout (no general path). */
#ifndef PROPID_SIZE_LEAN
#define PROPID_SIZE_LEAN 0
#endif
#if PROPID_SIZE_LEAN && PROPID_GENERAL_VEHICLES
#error "PROPID_SIZE_LEAN needs the quad build (PROPID_QUAD_BUILD=1, every optional model term off)"
#endif

/* State layout: body rate (3), thrust coefficient (N), drag coefficient (N),
 * gyro bias (3), then the optional blocks. With PROPID_MAX_ROTORS = 8 the largest
 * filter has 27 states. */
#define PROPID_RATE_STATES 3
#define PROPID_BIAS_STATES 3
/* Optional blocks the configuration may enable after them: disturbance torque (3),
 * accelerometer z bias (1), the accelerometer row's model error (1, right after the
 * bias), thrust-torque scale (1, with the accelerometer); 0 when compiled out. The
 * row's model error takes no room of its own in PROPID_MAX_STATES: every other block
 * fits beside it but for PROPID_MAX_ROTORS rotors with all three others on (then the
 * configuration is refused, naming accel_error_std). */
#define PROPID_DISTURBANCE_STATES (3 * PROPID_WITH_DISTURBANCE)
#define PROPID_ACCEL_BIAS_STATES (1 * PROPID_WITH_ACCEL)
#define PROPID_ACCEL_ERROR_STATES (1 * PROPID_WITH_ACCEL)
#define PROPID_TORQUE_SCALE_STATES (1 * PROPID_WITH_ACCEL)
/* Kinds of state (each shares its noise, prior and bounds): rate, thrust, drag,
 * gyro bias, then the optional disturbance, accelerometer bias, torque scale,
 * accelerometer model error. */
#define PROPID_STATE_KINDS (4 + PROPID_WITH_DISTURBANCE + 3 * PROPID_WITH_ACCEL)
#define PROPID_MAX_STATES (PROPID_RATE_STATES + 2 * PROPID_MAX_ROTORS + PROPID_BIAS_STATES + \
                           PROPID_DISTURBANCE_STATES + PROPID_ACCEL_BIAS_STATES + PROPID_TORQUE_SCALE_STATES)

/* 1: the model-consistency monitor (propid_consistency.c) watches the gyro
 * innovations, raises PROPID_HEALTH_MODEL_MISMATCH and widens the coefficient
 * covariance when they are inconsistent; 0 leaves it out (smaller filter). */
#ifndef PROPID_CONSISTENCY
#define PROPID_CONSISTENCY PROPID_DEFAULT_FEATURES /* the quad build: left out */
#endif

#if PROPID_MAX_ROTORS < 1 || PROPID_MAX_ROTORS > 16
#error "PROPID_MAX_ROTORS must be in 1..16"
#endif

/* Telemetry-delay buffer (docs/math.md §12): samples of the leading stream held
 * until the lagging one catches up. Its capacity bounds config.rotor_delay_us
 * (propid_config_check). 0 compiles the buffer out: every nonzero delay is then
 * a configuration error and propid_filter_t is that much smaller. */
#ifndef PROPID_DELAY_SLOTS
#define PROPID_DELAY_SLOTS (PROPID_DEFAULT_FEATURES ? 32 : 0) /* the quad build: compiled out */
#endif

#if PROPID_DELAY_SLOTS < 0 || PROPID_DELAY_SLOTS > 255
#error "PROPID_DELAY_SLOTS must be in 0..255"
#endif

#endif /* PROPID_CONFIG_H */
