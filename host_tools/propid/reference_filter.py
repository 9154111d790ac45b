"""Float64 numpy reference of the firmware filter (firmware/src/propid_*.c).

The SAME algorithm, step for step: scaled state [rate(3), kf/kf_nom(N), km/km_nom(N),
gyro bias(3)] (the km block kept, in the state and P, in the yaw basis of docs/math.md §2,
mapped to per rotor at the boundary as in C), prediction with the trapezoid input and Heun on the gyroscopic
term, P := F P F^T + Q dt, three sequential scalar gyro updates (x, y, z) with the
symmetric rank-one form, innovation gate with re-opening, coefficient clamps,
variance floors/ceilings, the round-robin covariance integrity check and repair,
the optional stuck-gyro check (gyro_stuck_samples), and the same input guards and
status codes. Only the arithmetic differs
(float64 here, float32 in C), which is what tests/host_tools/test_reference_vs_c.py
measures. Written for clarity, not speed: dense numpy where it is clearer.

Inputs are rounded to float32 on entry (config, rotor speeds, gyro), exactly as
they reach the C filter, so that both filters see identical numbers.
"""

from __future__ import annotations

import math
import struct
from typing import Sequence

import numpy as np

from propid.cfilter import DELAY_SLOTS, HEALTH, MODEL_TERMS, STATUS, Estimate, FilterConfig, health_names
from propid.reference_instrument import FirstStage

_F32_MAX = float(np.finfo(np.float32).max)
# Covariance health constants of the C filter (propid_internal.h): the rounding
# loading of every variance per prediction, and the rounding tolerance of the
# integrity tests. Float32 quantities on purpose: the reference mirrors the C
# algorithm, whose P needs them (docs/math.md §2).
VAR_LOADING = float(np.finfo(np.float32).eps)
ROUNDING_TOL = 2.0 * VAR_LOADING
UPDATE_LOADING = 64.0 * VAR_LOADING
ROTOR_SPEED_NOISE_TIME_MAX = 600.0  # C: PROPID_ROTOR_SPEED_NOISE_TIME_MAX [s]
GATE_OFF_SQ = 1.0e30  # C: PROPID_GATE_OFF_SQ (gating off still refuses 1e15-sigma innovations)


# C: PROPID_INPUT_ERROR_MAX_SHARE (propid_internal.h): the input-error compensation applies while the
# error explains at most this share of the information about the coefficients' common scale.
INPUT_ERROR_MAX_SHARE = 0.5


def _f32(value: float) -> float:
    return float(np.float32(value))


class ReferenceFilter:
    """Mirror of propid_filter_t and the propid_* functions, in float64.

    loadings=False is an experiment, not the C algorithm: the float32 covariance-health
    loadings are left out (the prediction's loading of every variance, the rates' included,
    and the update loading; docs/math.md §2; the rate variance keeps its ceiling), so the
    filter is the plain EKF of the same model, which float64 can carry (docs/reliability.md, "The
    loading's cost, measured in float64")."""

    def __init__(self, config: FilterConfig, loadings: bool = True, rate_coordinate: str = "body"):
        if rate_coordinate not in ("body", "gyro"):
            raise ValueError(f"reference filter: rate_coordinate {rate_coordinate!r} (body or gyro)")
        self.config = config
        # "gyro" is an experiment, not the C algorithm: the loadings the same filter takes with the
        # rate kept in the gyro's coordinate s = omega + b (docs/math.md, "What it costs where the bias
        # is not learnt"); exact arithmetic does the rest the same in either coordinate.
        self.rate_coordinate = rate_coordinate
        self.var_loading = VAR_LOADING if loadings else 0.0
        self.update_loading = UPDATE_LOADING if loadings else 0.0
        self.rotor_count = n_rot = config.rotor_count
        self.first_drag = 3 + n_rot
        self.first_bias = 3 + 2 * n_rot
        # Optional blocks after the gyro biases (propid_layout_t): disturbance (3), accel-z bias (1).
        nxt = self.first_bias + 3
        self.first_disturbance = None
        self.accel_bias = None
        if int(config.disturbance_torque):
            self.first_disturbance, nxt = nxt, nxt + 3
        if float(config.mass) > 0.0:
            self.accel_bias, nxt = nxt, nxt + 1
        self.torque_scale = None
        if int(config.torque_scale):
            self.torque_scale, nxt = nxt, nxt + 1
        self.n = nxt
        # The coefficients' bases (C: propid_internal.h, docs/math.md §2): the state and P keep
        # the kf block as z = Q kf_rel (Q = H_1 H_0: first rows the roll- and pitch-torque
        # directions, thrust_torque_basis below) and the km block as z = H km_rel (H = I - 2 v v^T
        # / v.v, v = e_0 + s_0 s / sqrt(N): first row the yaw torque). `basis` is T, the kept
        # state T x of the per-rotor x (Q and H on their blocks, identity elsewhere); T is
        # orthogonal: per rotor x = T^T z.
        yaw_signs = np.array([_f32(v) for v in config.yaw_signs])
        v = yaw_signs[0] * yaw_signs / math.sqrt(n_rot)
        v[0] += 1.0
        self.basis = np.eye(self.n)
        self.basis[self.first_drag:self.first_bias, self.first_drag:self.first_bias] = (
            np.eye(n_rot) - 2.0 * np.outer(v, v) / float(v @ v))
        c = {name: _f32(getattr(config, name)) for name in (
            "rate_std0", "thrust_coeff_rel_std0", "drag_coeff_rel_std0", "gyro_bias_std0",
            "gyro_noise_density", "gyro_sample_rate_hz", "rate_process_noise",
            "thrust_coeff_rel_walk", "drag_coeff_rel_walk", "gyro_bias_walk", "gate_sigma",
            "max_rotor_speed", "gyro_range", "coeff_rel_min", "coeff_rel_max", "converged_rel_std",
            "disturbance_std0", "disturbance_walk", "disturbance_bandwidth", "mass", "accel_noise_std",
            "accel_bias_std0", "accel_bias_walk", "accel_range", "torque_scale_std0", "torque_scale_walk")}
        self.c = c
        if float(getattr(config, "accel_error_std", 0.0)) > 0.0:
            # The accelerometer row's model-error state (C: propid_predict.c) is not mirrored here.
            raise ValueError("reference filter: accel_error_std > 0 is not modelled")
        self.gate_max_consecutive = int(config.gate_max_consecutive)
        # A gyro axis repeating its reading bit for bit this many samples is not fused (0: off).
        self.gyro_stuck_samples = int(getattr(config, "gyro_stuck_samples", 0))
        self.rotor_stale_us = int(config.rotor_stale_us)
        self.max_gyro_gap_us = int(config.max_gyro_gap_us)
        # Telemetry delay (docs/math.md §12, C: propid_delay.c): > 0 the IMU samples are held,
        # < 0 the rotor samples; the C buffer's capacity (cfilter.DELAY_SLOTS) is mirrored.
        self.rotor_delay_us = int(getattr(config, "rotor_delay_us", 0))
        self.imu_shift = max(self.rotor_delay_us, 0)
        self.rotor_shift = max(-self.rotor_delay_us, 0)
        self.held: list[tuple[int, str, list[float]]] = []  # (time, kind, values), oldest first

        inertia = np.array([[_f32(v) for v in row] for row in config.inertia])
        self.inertia = 0.5 * (inertia + inertia.T)
        self.inertia_inv = np.linalg.inv(self.inertia)
        positions = np.array([[_f32(v) for v in p] for p in config.positions])
        yaw = np.array([_f32(v) for v in config.yaw_signs])
        self.kf_nominal = np.array([_f32(v) for v in config.thrust_coeff_nominal])
        self.km_nominal = np.array([_f32(v) for v in config.drag_coeff_nominal])
        # thrust_torque[i] = J^-1 (r_i x z) kf_nom_i ; drag_torque[i] = J^-1 z s_i km_nom_i
        arm = np.stack([positions[:, 1], -positions[:, 0], np.zeros(n_rot)], axis=1)
        self.thrust_torque = (arm @ self.inertia_inv.T) * self.kf_nominal[:, None]
        self.drag_torque = np.outer(yaw * self.km_nominal, self.inertia_inv[:, 2])
        self.basis[3:self.first_drag, 3:self.first_drag] = thrust_torque_basis(
            self.thrust_torque[:, 0], self.thrust_torque[:, 1])
        # Rotor inertia (docs/math.md §8): h = sum_i yaw_sign_i J_r,i Omega_i; yaw reaction
        # J^-1 z yaw_sign_i J_r,i dOmega_i/dt; gyroscopic torque h (omega_y, -omega_x, 0).
        rotor_inertia = np.array([_f32(v) for v in (config.rotor_inertia or [0.0] * n_rot)])
        self.rotor_inertia_on = bool(np.any(rotor_inertia > 0.0))
        self.rotor_momentum = yaw * rotor_inertia
        self.rotor_reaction = np.outer(self.rotor_momentum, self.inertia_inv[:, 2])
        # Known aerodynamic rate damping (docs/math.md §17): omega_dot += -J^-1 D omega, D diagonal.
        damping = np.array([_f32(v) for v in (getattr(config, "aero_damping", None) or [0.0] * 3)])
        self.aero_rate = -self.inertia_inv * damping[None, :]
        self.aero_damping_on = bool(np.any(damping > 0.0))
        if c["mass"] > 0.0:
            self.thrust_per_mass = self.kf_nominal / c["mass"]
            self.accel_var = c["accel_noise_std"] ** 2

        self.gyro_var = c["gyro_noise_density"] ** 2 * c["gyro_sample_rate_hz"]
        if c["gate_sigma"] > 0.0:
            self.gate_sq = c["gate_sigma"] ** 2
            self.inv_gate_sq = 1.0 / self.gate_sq
        else:
            self.gate_sq, self.inv_gate_sq = GATE_OFF_SQ, 1.0
        self.rate_limit = 2.0 * c["gyro_range"]
        self.input_noise_var = 4.0 * _f32(config.rotor_speed_noise) ** 2
        self.input_noise_time = _f32(config.rotor_speed_noise_time)
        self.input_compensation = bool(getattr(config, "input_error_compensation", 0))
        self.input_noise_hold = int(getattr(config, "rotor_speed_noise_hold", 0))  # 0, 1 or 2 (floor)
        # C (propid_config.c): split, the spread's q^2 / 12 of the RMS q^2 / 3, the mean's 3x that
        self.input_noise_split = bool(getattr(config, "rotor_speed_noise_split", 0))
        if self.input_noise_split:
            self.input_noise_var *= 0.25
        # The report's timing error [s], one per report (C: add_input_noise's timing block, docs/math.md §14)
        self.input_timing_error = _f32(getattr(config, "rotor_timing_error", 0.0))
        self.converged_var = c["converged_rel_std"] ** 2
        # C (propid_config.c): a claim counts the configured inertia's scale error too, which
        # the data cannot see (for kf not when the torque-scale state takes it).
        inertia_var = _f32(getattr(config, "inertia_rel_std", 0.0)) ** 2
        self.claim_var = (self.converged_var / 9.0 - (0.0 if self.torque_scale is not None else inertia_var),
                          self.converged_var / 9.0 - inertia_var)

        self.rate_terms, self.rate_entries = self._rate_row_terms()

        n = self.n
        self.prior_var = np.empty(n)
        self.process_psd = np.empty(n)
        self.var_floor = np.empty(n)
        self.var_ceiling = np.empty(n)
        coeff_ceiling = c["coeff_rel_max"] ** 2
        for k in range(n):
            if k < 3:
                prior, psd, floor, ceiling = (c["rate_std0"] ** 2, c["rate_process_noise"] ** 2,
                                              1e-12, 4.0 * c["gyro_range"] ** 2)
            elif k < self.first_drag:
                prior, psd, floor, ceiling = (c["thrust_coeff_rel_std0"] ** 2,
                                              c["thrust_coeff_rel_walk"] ** 2, 1e-14, coeff_ceiling)
            elif k < self.first_bias:
                prior, psd, floor, ceiling = (c["drag_coeff_rel_std0"] ** 2,
                                              c["drag_coeff_rel_walk"] ** 2, 1e-10, coeff_ceiling)
            elif k < self.first_bias + 3:
                prior, psd, floor, ceiling = (c["gyro_bias_std0"] ** 2, c["gyro_bias_walk"] ** 2,
                                              1e-14, c["gyro_range"] ** 2)
            elif k == self.accel_bias:
                prior, psd, floor, ceiling = (c["accel_bias_std0"] ** 2, c["accel_bias_walk"] ** 2,
                                              1e-12, c["accel_range"] ** 2)
            elif k == self.torque_scale:
                prior, psd, floor, ceiling = (c["torque_scale_std0"] ** 2, c["torque_scale_walk"] ** 2, 1e-10,
                                              coeff_ceiling)
            else:  # disturbance
                prior, psd, floor = c["disturbance_std0"] ** 2, c["disturbance_walk"] ** 2, 1e-12
                if c["disturbance_bandwidth"] > 0.0:  # C: the walk from the bandwidth (math.md §7)
                    walk = _f32(_f32(_f32(2.0 * np.pi) * c["disturbance_bandwidth"]) * c["rate_process_noise"])
                    psd = walk * walk
                ceiling = 100.0 * prior
            if k < 3:
                # C: the rate variance is kept below R / (64 epsilon) (float32 rounding),
                # whatever the prior, and the rate prior is held at that ceiling.
                ceiling = max(min(ceiling, self.gyro_var / UPDATE_LOADING), floor)
                prior = min(prior, ceiling)
            self.prior_var[k] = prior
            self.process_psd[k] = psd
            self.var_floor[k] = floor
            self.var_ceiling[k] = max(ceiling, prior)

        self.counters_data = {
            "gyro_accepted": 0, "rotor_accepted": 0, "axis_gated": [0, 0, 0], "gate_reopened": 0,
            "cov_repairs": 0, "state_clamps": 0, "resyncs": 0, "rejected": [0] * 16,
            "accel_accepted": 0, "accel_gated": 0, "accel_reanchored": 0, "delay_overflows": 0,
            "command_accepted": 0, "instrument_inputs": 0, "instrument_guarded": 0, "gyro_stuck": 0,
        }
        # The motor commands' first stage (C: propid_instrument.c), when configured.
        self.instrument = None
        if int(getattr(config, "motor_command_instrument", 0)):
            self.instrument = FirstStage(n_rot, _f32(config.motor_command_lag), _f32(config.motor_command_memory),
                                         _f32(config.max_rotor_speed), int(config.rotor_stale_us),
                                         int(config.max_gyro_gap_us),
                                         _f32(getattr(config, "motor_command_min_f", 0.0)))
        self._core_to_prior()

    def _rate_row_terms(self) -> tuple[np.ndarray, np.ndarray]:
        """Terms of each rate row of F = I + G the C prediction lists (propid_config.c,
        derive_quad_layout / derive_sparsity): 1 for the rate itself + the row's Jacobian
        entries; the count m of the rounding scale's Cauchy-Schwarz bound (docs/math.md §2).
        And how many of those entries are rate columns (in the gyro's coordinate each is on
        the bias of that axis too)."""
        n_rot = self.rotor_count
        # A_ab = sum_c coeff[a, b, c] omega_c: the gyroscopic Jacobian at each unit rate
        coeff = np.stack([-(self.inertia_inv @ (_skew(e) @ self.inertia - _skew(self.inertia @ e)))
                          for e in np.eye(3)], axis=2)
        thrust = self.thrust_torque != 0.0
        drag = self.drag_torque != 0.0
        third_only = all(coeff[a, b, c] == 0.0 for a in range(3) for b in range(3) for c in range(3)
                         if not (a != b and c != a and c != b))
        if (n_rot == 4 and self.n == 3 + 2 * n_rot + 3 and not self.rotor_inertia_on and not self.aero_damping_on
                and third_only
                and not drag[:, :2].any() and not thrust[:, 2].any()):
            # the fixed quad layout: 2 rates + 4 coefficients a row
            return np.full(3, 1.0 + 6.0), np.full(3, 2.0)
        terms = np.ones(3)
        rate_entries = np.zeros(3)
        for a in range(3):
            for b in range(3):
                rotor_term = self.rotor_inertia_on and b < 2 and self.inertia_inv[a, 1 - b] != 0.0
                damping_term = self.aero_rate[a, b] != 0.0
                rate_entries[a] += bool(np.any(coeff[a, b] != 0.0) or rotor_term or damping_term)
            terms[a] += rate_entries[a]
            terms[a] += np.count_nonzero(thrust[:, a])
            terms[a] += n_rot if drag[:, a].any() else 0
            terms[a] += 1 if self.first_disturbance is not None else 0
        return terms, rate_entries

    # ------------------------------------------------------------------ life cycle
    def _core_to_prior(self) -> None:
        n = self.n
        self.state = np.zeros(n)
        self.state[3:self.first_bias] = 1.0
        if self.torque_scale is not None:
            self.state[self.torque_scale] = 1.0  # r = 1/s
        self.cov = np.diag(self.prior_var.copy())
        if self.torque_scale is not None:
            # C (propid_cov_set_prior): g = s kf, r = 1/s from independent kf and s priors, to first order
            r, g = self.torque_scale, slice(3, self.first_drag)
            p_s = self.prior_var[r]
            self.cov[g, g] += p_s
            self.cov[g, r] = self.cov[r, g] = -p_s
        # Into the kept bases (equal priors within a block: only the torque scale's terms move).
        self.state = self.basis @ self.state
        self.cov = self.basis @ self.cov @ self.basis.T
        self.rotor_speed_sq = np.zeros(self.rotor_count)
        self.input_speed_sq = np.zeros(self.rotor_count)
        self.rotor_time_us = 0
        self.time_us = 0
        self.has_rotor_data = False
        self.has_time = False
        self.gated_run = [0, 0, 0]
        # Per axis the last reading's bits and how many readings in a row had them
        # (C: gyro_last_bits, gyro_repeat_run; cleared here, kept by resync).
        self.gyro_last_bits = [0, 0, 0]
        self.gyro_repeat_run = [0, 0, 0]
        self.accel_gated_run = 0
        self.has_accel = False
        self.accel_time_us = 0
        self.accel_innovation = 0.0
        self.accel_innovation_test_ratio = 0.0
        self.health = 0
        self.innovation = np.zeros(3)
        self.innovation_test_ratio = np.zeros(3)
        self.stale_mark = self.counters_data["rejected"][-STATUS["PROPID_ERR_ROTOR_STALE"]]
        self.check_row = 0
        self.held = []
        # The input-error compensation's memory and validity statistics (C: propid_core_t input_*).
        self.input_error_carried = np.zeros(3)
        self.input_error_cross = np.zeros(3)
        self.input_information = np.zeros(3)
        self.input_error_information = np.zeros(3)
        self.input_information_time = 0.0
        # Per rotor, how long its input value has stood (C: input_hold_age).
        self.input_hold_age = np.zeros(self.rotor_count)
        if self.instrument is not None:
            self.instrument.clear()

    def reset(self) -> int:
        self._core_to_prior()
        return STATUS["PROPID_OK"]

    def _reset_state(self, k: int) -> None:
        self.cov[k, :] = 0.0
        self.cov[:, k] = 0.0
        self.cov[k, k] = self.prior_var[k]

    def reset_rotor(self, rotor: int) -> int:
        if not 0 <= rotor < self.rotor_count:
            return self._reject("PROPID_ERR_ROTOR_INDEX")
        self._flip_basis(to_rotor=True)  # per rotor around the reset (C: propid_cov_reset_rotor)
        for k in (3 + rotor, self.first_drag + rotor):
            self.state[k] = 1.0
            self._reset_state(k)
        if self.torque_scale is not None:  # the nominal kf is g = 1/r
            self.state[3 + rotor] = 1.0 / self.state[self.torque_scale]
        self._flip_basis(to_rotor=False)
        return STATUS["PROPID_OK"]

    def _flip_basis(self, to_rotor: bool) -> None:
        """State and P between the kept bases and per rotor."""
        t = self.basis.T if to_rotor else self.basis
        self.state = t @ self.state
        self.cov = t @ self.cov @ t.T

    def _per_rotor_state(self) -> np.ndarray:
        return self.basis.T @ self.state

    def _per_rotor_cov(self) -> np.ndarray:
        return self.basis.T @ self.cov @ self.basis

    def resync(self, t_us: int) -> int:
        for a in range(3):
            self.state[a] = 0.0
            self._reset_state(a)
            self.gated_run[a] = 0
        self.time_us = int(t_us)
        self.has_time = False
        self.held = []
        self.health |= HEALTH["TIME_RESYNCED"]
        self.counters_data["resyncs"] += 1
        return STATUS["PROPID_OK"]

    def _reject(self, name: str) -> int:
        code = STATUS[name]
        self.counters_data["rejected"][-code] += 1
        return code

    # ------------------------------------------------------------------ model
    def _held_spans(self, dt: float, ceiling: float) -> np.ndarray:
        """The held error's span per rotor (C: held_span, docs/math.md §14): dt when the
        value changes within the step, else dt + 2 age, bounded by the configured time
        (hold 2: raised to it, bounded by the largest time)."""
        changed = self.rotor_speed_sq != self.input_speed_sq
        if self.input_noise_hold == 2:
            # C: held_span_floor: the configured time is the floor, the largest time the ceiling.
            largest = ROTOR_SPEED_NOISE_TIME_MAX
            held = np.where(changed, dt, dt + 2.0 * self.input_hold_age)
            self.input_hold_age = np.where(changed, 0.0, np.minimum(self.input_hold_age + dt, largest))
            return np.minimum(np.maximum(held, ceiling), largest)
        span = np.where(changed, dt, np.minimum(dt + 2.0 * self.input_hold_age, ceiling))
        self.input_hold_age = np.where(changed, 0.0, np.minimum(self.input_hold_age + dt, ceiling))
        return span

    def rate_derivative_and_jacobian(self, state: np.ndarray, speed_sq: np.ndarray, momentum_z: float = 0.0):
        """Angular acceleration and its Jacobian rows (3 x n); momentum_z = sum_i yaw_sign_i J_r,i
        Omega_i (rotor inertia; the yaw reaction is added by the caller, it does not depend on x)."""
        n_rot = self.rotor_count
        rate = state[:3]
        kf_rel = state[3:3 + n_rot]
        km_rel = state[3 + n_rot:3 + 2 * n_rot]
        momentum = self.inertia @ rate
        gyroscopic = np.cross(rate, momentum)
        # (with the torque scale the thrust states carry g = s kf: the row stays linear)
        thrust_part = (kf_rel * speed_sq) @ self.thrust_torque
        rate_dot = (-(self.inertia_inv @ gyroscopic)
                    + thrust_part
                    + (km_rel * speed_sq) @ self.drag_torque)
        # d(omega x J omega)/d omega = [omega]x J - [J omega]x
        dgyro = _skew(rate) @ self.inertia - _skew(momentum)
        rows = np.zeros((3, self.n))
        rows[:, :3] = -(self.inertia_inv @ dgyro)
        rows[:, 3:3 + n_rot] = (self.thrust_torque * speed_sq[:, None]).T
        rows[:, 3 + n_rot:3 + 2 * n_rot] = (self.drag_torque * speed_sq[:, None]).T
        if momentum_z != 0.0:
            rotor_gyro = np.zeros((3, 3))
            rotor_gyro[:, 0] = -self.inertia_inv[:, 1] * momentum_z
            rotor_gyro[:, 1] = self.inertia_inv[:, 0] * momentum_z
            rate_dot = rate_dot + rotor_gyro @ rate
            rows[:, :3] += rotor_gyro
        if self.aero_damping_on:
            rate_dot = rate_dot + self.aero_rate @ rate
            rows[:, :3] += self.aero_rate
        if self.first_disturbance is not None:
            d = self.first_disturbance
            rate_dot = rate_dot + state[d:d + 3]
            rows[:, d:d + 3] = np.eye(3)
        return rate_dot, rows

    # ------------------------------------------------------------------ covariance
    def _repair(self) -> bool:
        n = self.n
        changed = False
        for i in range(n):
            p = self.cov[i, i]
            if not (p > 0.0 and p <= _F32_MAX):
                self._reset_state(i)
                changed = True
        for i in range(n):
            for j in range(i + 1, n):
                pij = self.cov[i, j]
                limit_sq = self.cov[i, i] * self.cov[j, j]
                fixed = pij
                if not math.isfinite(pij):
                    fixed = 0.0
                elif pij * pij > limit_sq * (1.0 + ROUNDING_TOL):
                    limit = 0.99 * math.sqrt(limit_sq)
                    fixed = limit if pij > 0.0 else -limit
                if fixed != pij or self.cov[j, i] != pij:
                    self.cov[i, j] = self.cov[j, i] = fixed
                    changed = True
        return changed

    def _check_row(self, row: int) -> bool:
        pii = self.cov[row, row]
        bad = not (pii > 0.0 and pii <= _F32_MAX)
        if not bad:
            # The part of the row right of the diagonal (C: every element once per n samples).
            r = self.cov[row, row + 1:]
            with np.errstate(invalid="ignore", over="ignore"):
                bad = bool(np.any(~(r * r <= pii * (1.0 + ROUNDING_TOL) * np.diag(self.cov)[row + 1:]))
                           or np.any(self.cov[row + 1:, row] != r))
        return self._repair() if bad else False

    def _enforce_bounds(self) -> bool:
        repaired = False
        for i in range(self.n):
            p = self.cov[i, i]
            if not (p > 0.0 and p <= _F32_MAX):
                repaired |= self._repair()
            elif p < self.var_floor[i]:
                self.cov[i, i] = self.var_floor[i]
            elif p > self.var_ceiling[i]:
                c = self.var_ceiling[i] / p
                self.cov[i, :] *= c
                self.cov[:, i] = self.cov[i, :]
                self.cov[i, i] = self.var_ceiling[i]
        return repaired

    # ------------------------------------------------------------------ inputs
    def push_rotor_speeds(self, t_us: int, speeds: Sequence[float]) -> int:
        if len(speeds) != self.rotor_count:
            return self._reject("PROPID_ERR_ROTOR_COUNT")
        values = [_f32(v) for v in speeds]
        for v in values:
            if not math.isfinite(v):
                return self._reject("PROPID_ERR_NOT_FINITE")
            if v < 0.0:
                return self._reject("PROPID_ERR_ROTOR_SPEED_NEGATIVE")
            if v > self.c["max_rotor_speed"]:
                return self._reject("PROPID_ERR_ROTOR_SPEED_RANGE")
        max_gap = self.max_gyro_gap_us
        stamp = int(t_us) + self.rotor_shift
        held = [h for h in self.held if h[1] == "rotor"]
        previous, has_previous = (held[-1][0], True) if held else (self.rotor_time_us, self.has_rotor_data)
        if has_previous and stamp <= previous:
            # ... unless the stored stamp is the clock fault (C: same rule).
            reference = self.time_us + self.imu_shift if self.has_time else stamp
            if not previous - reference > max_gap:
                return self._reject("PROPID_ERR_TIME_BACKWARDS")
            if held:
                self.held = []
        speed_sq = [v * v for v in values]
        if self.instrument is not None:
            speed_sq, projected, guarded = self.instrument.input(int(t_us), speed_sq)
            self.counters_data["instrument_inputs"] += int(projected)
            self.counters_data["instrument_guarded"] += guarded
        if self.rotor_delay_us < 0:
            if len(self.held) >= DELAY_SLOTS:
                self._apply_held_rotor()
                self.counters_data["delay_overflows"] += 1
            self.held.append((stamp, "rotor", speed_sq))
            self.counters_data["rotor_accepted"] += 1
            return STATUS["PROPID_OK_QUEUED"]
        if self.rotor_delay_us > 0:
            self._release_imu(stamp, inclusive=False)
        self.rotor_speed_sq = np.array(speed_sq)
        self.rotor_time_us = stamp
        self.has_rotor_data = True
        self.counters_data["rotor_accepted"] += 1
        return STATUS["PROPID_OK"]

    def push_motor_command(self, t_us: int, command: Sequence[float]) -> int:
        """Mirror of propid_push_motor_command (propid_instrument.c)."""
        if self.instrument is None:
            return self._reject("PROPID_ERR_CONFIG")
        if len(command) != self.rotor_count:
            return self._reject("PROPID_ERR_ROTOR_COUNT")
        values = [_f32(v) for v in command]
        for v in values:
            if not math.isfinite(v):
                return self._reject("PROPID_ERR_NOT_FINITE")
            if v < 0.0 or v > 1.0:
                return self._reject("PROPID_ERR_ROTOR_SPEED_RANGE")
        if self.instrument.has_command and int(t_us) <= self.instrument.command_time_us:
            return self._reject("PROPID_ERR_TIME_BACKWARDS")
        self.instrument.push(int(t_us), np.array(values))
        self.counters_data["command_accepted"] += 1
        return STATUS["PROPID_OK"]

    # ------------------------------------------------------------------ telemetry delay
    def _apply_held_rotor(self) -> None:
        stamp, _, speed_sq = self.held.pop(0)
        self.rotor_speed_sq = np.array(speed_sq)
        self.rotor_time_us = stamp
        self.has_rotor_data = True

    def _release_rotor(self, t_us: int) -> None:
        while self.held and self.held[0][0] <= t_us:
            self._apply_held_rotor()

    def _fuse_held_imu(self) -> None:
        stamp, kind, values = self.held.pop(0)
        if kind == "gyro":
            self._fuse_gyro(stamp, values)
        else:
            self._fuse_accel(stamp, values)

    def _release_imu(self, t_us: int, inclusive: bool) -> None:
        while self.held:
            due = self.held[0][0] + self.imu_shift
            if (due > t_us) if inclusive else (due >= t_us):
                break
            self._fuse_held_imu()

    def _hold_imu(self, t_us: int, kind: str, values: list[float]) -> int:
        self._release_imu(t_us, inclusive=True)
        if len(self.held) >= DELAY_SLOTS:
            self._fuse_held_imu()
            self.counters_data["delay_overflows"] += 1
        self.held.append((int(t_us), kind, list(values)))
        return STATUS["PROPID_OK_QUEUED"]

    def push_gyro(self, t_us: int, gyro: Sequence[float]) -> int:
        y = [_f32(v) for v in gyro]
        if not all(math.isfinite(v) for v in y):
            return self._reject("PROPID_ERR_NOT_FINITE")
        if any(abs(v) > self.c["gyro_range"] for v in y):
            return self._reject("PROPID_ERR_GYRO_RANGE")
        if self.rotor_delay_us > 0:
            held = [h for h in self.held if h[1] == "gyro"]
            previous, anchor = (held[-1][0], False) if held else (self.time_us, not self.has_time)
            if anchor and t_us < previous or not anchor and t_us <= previous:
                return self._reject("PROPID_ERR_TIME_BACKWARDS")
            if not anchor and t_us - previous > self.max_gyro_gap_us:
                return self._reject("PROPID_ERR_TIME_JUMP")
            return self._hold_imu(t_us, "gyro", y)
        return self._fuse_gyro(t_us, y)

    def _fuse_gyro(self, t_us: int, y: list[float]) -> int:
        anchor = not self.has_time
        dt = 0.0
        if anchor:
            if t_us < self.time_us:
                return self._reject("PROPID_ERR_TIME_BACKWARDS")
        else:
            if t_us <= self.time_us:
                return self._reject("PROPID_ERR_TIME_BACKWARDS")
            gap = t_us - self.time_us
            if gap > self.max_gyro_gap_us:
                return self._reject("PROPID_ERR_TIME_JUMP")
            dt = gap * 1e-6
        if self.rotor_delay_us < 0:
            self._release_rotor(t_us)
        if not self.has_rotor_data:
            return self._reject("PROPID_ERR_NO_ROTOR_DATA")
        rotor_clock = t_us + self.imu_shift  # the gyro stamp on the rotor stream's clock
        if rotor_clock > self.rotor_time_us and rotor_clock - self.rotor_time_us > self.rotor_stale_us:
            return self._reject("PROPID_ERR_ROTOR_STALE")
        if self.rotor_time_us - rotor_clock > self.max_gyro_gap_us:
            return self._reject("PROPID_ERR_ROTOR_STALE")
        if not anchor:
            # Trapezoid input over the interval, as the C filter (docs/math.md).
            speed_sq = 0.5 * (self.input_speed_sq + self.rotor_speed_sq)
            momentum_z, reaction = 0.0, np.zeros(3)
            if self.rotor_inertia_on:
                start, end = np.sqrt(self.input_speed_sq), np.sqrt(self.rotor_speed_sq)
                momentum_z = float(self.rotor_momentum @ (0.5 * (start + end)))
                reaction = (end - start) @ self.rotor_reaction
            # The model per rotor, its Jacobian's drag columns then times H (the kept basis).
            model_state = self._per_rotor_state()
            rate_dot, rows = self.rate_derivative_and_jacobian(model_state, speed_sq, momentum_z)
            # Heun (docs/math.md §2): f again at the Euler predictor, averaged. Only
            # the gyroscopic part differs between the two (the rotor part does not
            # depend on omega), so this is the C filter's "Heun on the gyroscopic
            # term"; the Jacobian is the mean of the two (the gyroscopic Jacobian at
            # the midpoint, as it is linear in omega; the rotor columns are equal).
            predicted = model_state.copy()
            predicted[:3] = self.state[:3] + dt * rate_dot + reaction
            rate_dot_next, rows_next = self.rate_derivative_and_jacobian(predicted, speed_sq, momentum_z)
            rate_next = self.state[:3] + dt * 0.5 * (rate_dot + rate_dot_next) + reaction
            jac_dt = dt * 0.5 * (rows + rows_next) @ self.basis.T
            if not (np.all(np.isfinite(rate_next)) and np.all(np.isfinite(jac_dt))
                    and np.all(np.isfinite(self.state))):
                return self._reject("PROPID_ERR_NUMERIC")
            # Bounded prediction (C: propid_predict_stage, PROPID_PREDICT_CLAMPED).
            rate_clamped = int(np.any(np.abs(rate_next) > self.rate_limit))
            rate_next = np.clip(rate_next, -self.rate_limit, self.rate_limit)
        elif not np.all(np.isfinite(self.state)):
            return self._reject("PROPID_ERR_NUMERIC")

        # Accepted.
        self.health &= ~(HEALTH["GATED"] | HEALTH["STATE_CLAMPED"])
        if self._check_row(self.check_row):
            self.health |= HEALTH["COV_REPAIRED"]
            self.counters_data["cov_repairs"] += 1
        self.check_row = 0 if self.check_row + 1 >= self.n else self.check_row + 1

        if not anchor:
            n = self.n
            self._propagate_covariance(jac_dt, dt)
            if self.torque_scale is not None and self.process_psd[self.torque_scale] > 0.0:
                # C: add_scale_walk, Q dt = q^2 dt v v^T, v = r g at each g and -r^2 at r (q^2 dt
                # on P_rr is in the per-state process noise already)
                r, g = self.torque_scale, slice(3, self.first_drag)
                v = np.zeros(n)
                v[g] = self.state[r] * self.state[g]
                v[r] = -self.state[r] ** 2
                self.cov += self.process_psd[r] * dt * np.outer(v, v)
                self.cov[r, r] -= self.process_psd[r] * dt
            if self.input_noise_var > 0.0 or self.input_timing_error > 0.0:
                # Rotor-speed input error (C: add_input_noise, docs/math.md §14): B Sigma_u B^T
                # dt max(dt, time), B = d(omega_dot)/d(Omega^2) at the current coefficients.
                n_rot = self.rotor_count
                coeffs = self._per_rotor_state()
                _, unit_rows = self.rate_derivative_and_jacobian(coeffs, np.ones(n_rot))
                gain = (unit_rows[:, 3:3 + n_rot] * coeffs[3:3 + n_rot]
                        + unit_rows[:, 3 + n_rot:3 + 2 * n_rot] * coeffs[3 + n_rot:3 + 2 * n_rot])
                span = np.full(n_rot, max(dt, self.input_noise_time))
                if self.input_noise_hold:
                    span = self._held_spans(dt, span[0])
                input_var = self.input_noise_var * speed_sq * dt * span
                self.cov[:3, :3] += (gain * input_var) @ gain.T
                if self.input_noise_split:
                    # C: add_common_block, an error common to every rotor over each rotor's span
                    along = gain @ np.sqrt(3.0 * self.input_noise_var * speed_sq * dt * span)
                    self.cov[:3, :3] += np.outer(along, along)
                if self.input_timing_error > 0.0:
                    # C: the report's timing, rank one: B tau (u_end - u_start) / dt, the speeds' squares as
                    # C rounds them (float32): the difference of two close squares keeps their rounding
                    change = (np.asarray(self.rotor_speed_sq, dtype=np.float32).astype(float)
                              - np.asarray(self.input_speed_sq, dtype=np.float32).astype(float))
                    along = gain @ (self.input_timing_error * change / dt)
                    self.cov[:3, :3] += np.outer(along, along)
            self.state[:3] = rate_next
        else:
            # The rates start at the anchoring sample (C: propid_push_gyro).
            self.state[:3] = np.array(y) - self.state[self.first_bias:self.first_bias + 3]
            rate_clamped = 0

        compensation = self._input_compensation_prepare(dt) if (self.input_compensation and not anchor) else None
        # Ceilings before the update (C: the general update path does this when it
        # runs; a no-op unless a variance is out of its bounds).
        if self._enforce_bounds():
            self.health |= HEALTH["COV_REPAIRED"]
            self.counters_data["cov_repairs"] += 1
        # The stuck-axis check (C: propid_gyro_stuck_mask), not on the anchoring sample.
        stuck = self._gyro_stuck_mask(y) if (self.gyro_stuck_samples and not anchor) else [False] * 3
        gated_axes = [self._skip_stuck_axis(axis) if stuck[axis] else self._update_axis(axis, y[axis])
                      for axis in range(3)]
        gated = any(gated_axes)
        if compensation is not None:
            self._input_compensation_apply(compensation, gated_axes)

        self._clamp(rate_clamped)
        if self._enforce_bounds():
            self.health |= HEALTH["COV_REPAIRED"]
            self.counters_data["cov_repairs"] += 1
        if gated:
            self.health |= HEALTH["GATED"]
        self.input_speed_sq = self.rotor_speed_sq.copy()
        self.time_us = int(t_us)
        self.has_time = True
        self.stale_mark = self.counters_data["rejected"][-STATUS["PROPID_ERR_ROTOR_STALE"]]
        self.counters_data["gyro_accepted"] += 1
        return STATUS["PROPID_OK_GATED"] if gated else STATUS["PROPID_OK"]

    def _propagate_covariance(self, jac_dt: np.ndarray, dt: float) -> None:
        """P := F P F^T + Q dt + the rounding loadings (C: propid_predict.c), F = I + jac_dt on the
        rate rows. rate_coordinate="gyro": the loadings the same algorithm takes with the rate kept
        as s = omega + b (below); F P F^T and Q dt are the same in either coordinate."""
        n = self.n
        f = np.eye(n)
        f[:3, :] += jac_dt
        diag = np.diag_indices(n)
        bias = slice(self.first_bias, self.first_bias + 3)
        variances = np.diag(self.cov)
        if self.rate_coordinate == "gyro":
            # Row a of F in (s, b): 1 on s_a, G_ac on s_c, -G_ac on b_c, G on the rest; its
            # diagonal: var(s_c) on the rates, P_bb on the biases, P on the rest.
            kept = variances.copy()
            kept[:3] = variances[:3] + 2.0 * np.diag(self.cov[:3, bias]) + variances[bias]
            squares = kept[:3] + (jac_dt ** 2) @ kept + (jac_dt[:, :3] ** 2) @ variances[bias]
            terms = self.rate_terms + self.rate_entries
        else:
            squares = variances[:3] + (jac_dt ** 2) @ variances
            terms = self.rate_terms
        # the rates' loading eps l m (P_aa + sum_p G_ap^2 P_pp), m = 1 + the row's listed
        # entries, l = max(8, m) (C: the prediction's rounding scale, docs/math.md §2)
        rate_scale = terms * np.maximum(terms, 8.0) * squares
        self.cov = f @ self.cov @ f.T
        self.cov = 0.5 * (self.cov + self.cov.T)
        # Q dt and the rounding loading (C: PROPID_VAR_LOADING, docs/math.md §2): on the
        # drag coefficients every second prediction (C: even check rows), on the rest every one;
        # the rates' of their rounding scale (above).
        loading = np.full(n, self.var_loading)
        if self.check_row % 2 != 0:
            loading[self.first_drag:self.first_bias] = 0.0
        scaled = self.cov[diag].copy()
        scaled[:3] = rate_scale
        if self.rate_coordinate == "gyro":
            # A bias loaded with s = omega + b held: + d on var(b) and var(omega), - d on their
            # covariance (var(omega + b) untouched).
            along = loading[bias] * scaled[bias]
            loading[bias] = 0.0
            rates = np.arange(3)
            biases = rates + self.first_bias
            self.cov[rates, rates] += along
            self.cov[biases, biases] += along
            self.cov[rates, biases] -= along
            self.cov[biases, rates] -= along
        self.cov[diag] += loading * scaled + self.process_psd * dt

    def _input_compensation_prepare(self, dt: float) -> dict:
        """C: propid_input_compensation_prepare (docs/math.md §14): each axis' errors-in-variables
        correction of the coefficients from the predicted P, and the validity statistics."""
        n_rot = self.rotor_count
        coeff = slice(3, 3 + 2 * n_rot)
        rotor_of = np.concatenate([np.arange(n_rot), np.arange(n_rot)])
        # Per rotor (the kept drag block is in its yaw basis); the corrections go back below.
        state = self._per_rotor_state()
        cov = self._per_rotor_cov()
        _, unit_rows = self.rate_derivative_and_jacobian(state, np.ones(n_rot))
        entry = unit_rows[:, coeff]  # d(omega_dot_a)/d(u_i) per unit coefficient, thrust then drag columns
        theta = state[coeff]
        p_coeff = cov[coeff, coeff]
        direction = p_coeff @ theta  # P theta: the common scale's direction
        input_var = 0.5 * self.input_noise_var * (self.input_speed_sq + self.rotor_speed_sq)
        tau = self.input_noise_time
        rho = math.exp(-dt / tau) if tau > 0.0 else 0.0
        self.input_information_time += dt
        share = dt / self.input_information_time
        out = {"correction": np.zeros((3, 2 * n_rot)), "rate_gain": np.zeros(3), "carried": np.zeros(3),
               "cross": np.zeros(3), "valid": [False] * 3}
        for a in range(3):
            bias = self.first_bias + a
            p_rate = cov[a, a] + cov[a, bias]
            innovation_var = p_rate + cov[a, bias] + cov[bias, bias] + self.gyro_var
            out["rate_gain"][a] = p_rate / innovation_var
            out["cross"][a] = rho * self.input_error_cross[a]
            out["carried"][a] = self.input_error_carried[a] + 2.0 * out["cross"][a] + 1.0
            weight = out["carried"][a] * dt * dt / innovation_var
            gain = np.bincount(rotor_of, weights=entry[a] * theta, minlength=n_rot)
            along = np.bincount(rotor_of, weights=entry[a] * direction, minlength=n_rot)
            cross_cov = float(theta @ (cov[coeff, a] + cov[coeff, bias]))
            self.input_information[a] += share * (cross_cov * cross_cov / innovation_var - self.input_information[a])
            error_information = weight * float(np.sum(input_var * along * along))
            self.input_error_information[a] += share * (error_information - self.input_error_information[a])
            out["valid"][a] = self.input_error_information[a] <= INPUT_ERROR_MAX_SHARE * self.input_information[a]
            factor = weight * input_var[rotor_of] * gain[rotor_of] * entry[a]
            out["correction"][a] = self.basis[coeff, coeff] @ (p_coeff @ factor)
        return out

    def _input_compensation_apply(self, compensation: dict, gated_axes: list[bool]) -> None:
        """C: propid_input_compensation_apply: the correction of each fused, valid axis; the memory."""
        coeff = slice(3, 3 + 2 * self.rotor_count)
        for a in range(3):
            fused = not gated_axes[a]
            kept = 1.0 - compensation["rate_gain"][a] if fused else 1.0
            if fused and compensation["valid"][a]:
                self.state[coeff] += compensation["correction"][a]
            self.input_error_cross[a] = kept * (compensation["cross"][a] + 1.0)
            self.input_error_carried[a] = kept * kept * compensation["carried"][a]

    def _gyro_stuck_mask(self, y: list[float]) -> list[bool]:
        """Per axis: has its reading repeated bit for bit gyro_stuck_samples times in a row?
        Bits, not values, as the C filter compares them (a stuck source repeats its word)."""
        mask = []
        for a in range(3):
            bits = struct.unpack("<I", struct.pack("<f", y[a]))[0]
            if bits == self.gyro_last_bits[a] and self.gyro_repeat_run[a] != 0:
                self.gyro_repeat_run[a] = min(self.gyro_repeat_run[a] + 1, 0xFFFF)
            else:
                self.gyro_last_bits[a] = bits
                self.gyro_repeat_run[a] = 1
            mask.append(self.gyro_repeat_run[a] >= self.gyro_stuck_samples)
        return mask

    def _skip_stuck_axis(self, axis: int) -> bool:
        """A stuck axis is not fused: neither the gate nor its re-anchor sees it (C:
        propid_update_gyro_skipping). Counts as not fused (the GATED flag)."""
        self.innovation_test_ratio[axis] = 0.0
        self.counters_data["gyro_stuck"] += 1
        return True

    def _update_axis(self, axis: int, gyro: float) -> bool:
        bias = self.first_bias + axis
        cov_h = self.cov[:, axis] + self.cov[:, bias]
        innovation_var = cov_h[axis] + cov_h[bias] + self.gyro_var
        # S >= R up to the rounding of the sum (C: PROPID_ROUNDING_TOL): var(omega + b)
        # within it of zero is zero, not a fault.
        # (C, propid_scalar_update: count * sum_k h_k^2 P_kk with H = e_rate + e_bias, count 2)
        rounding = ROUNDING_TOL * 2.0 * (self.cov[axis, axis] + self.cov[bias, bias])
        if innovation_var >= self.gyro_var - rounding:
            innovation_var = max(innovation_var, self.gyro_var)
        else:
            if self._repair():
                self.health |= HEALTH["COV_REPAIRED"]
                self.counters_data["cov_repairs"] += 1
            cov_h = self.cov[:, axis] + self.cov[:, bias]
            innovation_var = max(cov_h[axis] + cov_h[bias] + self.gyro_var, self.gyro_var)
        # Update loading (C: PROPID_UPDATE_LOADING): R_eff = 64 eps P_hh when larger.
        loaded_noise = self.update_loading * (innovation_var - self.gyro_var)
        if loaded_noise > self.gyro_var:
            innovation_var += loaded_noise - self.gyro_var
        innovation = gyro - self.state[axis] - self.state[bias]
        innovation_sq = innovation * innovation
        self.innovation[axis] = innovation
        self.innovation_test_ratio[axis] = innovation_sq / innovation_var * self.inv_gate_sq
        if not innovation_sq <= self.gate_sq * innovation_var:
            if self.gated_run[axis] < self.gate_max_consecutive:
                self.gated_run[axis] += 1
                self.counters_data["axis_gated"][axis] += 1
                return True
            # Re-anchor this axis' rate on the sample: rate := measurement - bias,
            # prior variance, no correlations; then fuse (C: reanchor_rate).
            self.state[axis] = _f32(gyro) - self.state[bias]
            self._reset_state(axis)
            cov_h = self.cov[:, axis] + self.cov[:, bias]
            innovation_var = cov_h[axis] + cov_h[bias] + self.gyro_var
            innovation = gyro - self.state[axis] - self.state[bias]
            self.counters_data["gate_reopened"] += 1
            self.health |= HEALTH["GATE_REOPENED"]
        self.gated_run[axis] = 0
        self._fuse(cov_h, innovation, innovation_var)
        return False

    def _fuse(self, cov_h: np.ndarray, innovation: float, innovation_var: float) -> None:
        """The scalar update's write (C: propid_scalar_update): state, covariance, variance bounds."""
        self.state += cov_h * (innovation / innovation_var)
        self.cov -= np.outer(cov_h, cov_h) / innovation_var
        self.cov = 0.5 * (self.cov + self.cov.T)
        if self._enforce_bounds():
            self.health |= HEALTH["COV_REPAIRED"]
            self.counters_data["cov_repairs"] += 1

    def push_accel(self, t_us: int, specific_force: Sequence[float]) -> int:
        """Mirror of propid_push_accel (propid_accel.c): z specific force = sum kf_i u_i / m + b_z."""
        if self.accel_bias is None:
            return self._reject("PROPID_ERR_CONFIG")
        f = [_f32(v) for v in specific_force]
        if not all(math.isfinite(v) for v in f):
            return self._reject("PROPID_ERR_NOT_FINITE")
        if any(abs(v) > self.c["accel_range"] for v in f):
            return self._reject("PROPID_ERR_ACCEL_RANGE")
        if self.rotor_delay_us > 0:
            held = [h for h in self.held if h[1] == "accel"]
            previous, has_previous = (held[-1][0], True) if held else (self.accel_time_us, self.has_accel)
            if has_previous and t_us <= previous:
                return self._reject("PROPID_ERR_TIME_BACKWARDS")
            return self._hold_imu(t_us, "accel", f)
        return self._fuse_accel(t_us, f)

    def _fuse_accel(self, t_us: int, f: list[float]) -> int:
        if self.has_accel and t_us <= self.accel_time_us:
            return self._reject("PROPID_ERR_TIME_BACKWARDS")
        if self.rotor_delay_us < 0:
            self._release_rotor(t_us)
        if not self.has_rotor_data:
            return self._reject("PROPID_ERR_NO_ROTOR_DATA")
        rotor_clock = t_us + self.imu_shift
        if rotor_clock > self.rotor_time_us and rotor_clock - self.rotor_time_us > self.rotor_stale_us:
            return self._reject("PROPID_ERR_ROTOR_STALE")
        n_rot, b = self.rotor_count, self.accel_bias
        # C: with the torque scale r = 1/s multiplies the thrust states g = s kf here only
        r = float(self.state[self.torque_scale]) if self.torque_scale is not None else 1.0
        # The row per rotor times Q^T: over the kept torque-basis states.
        per_state = self.basis[3:3 + n_rot, 3:3 + n_rot] @ (self.thrust_per_mass * self.rotor_speed_sq)
        h = np.zeros(self.n)
        h[3:3 + n_rot] = r * per_state
        h[b] = 1.0
        thrust_states = float(per_state @ self.state[3:3 + n_rot])
        if self.torque_scale is not None:
            h[self.torque_scale] = thrust_states
        thrust = r * thrust_states
        innovation = f[2] - thrust - self.state[b]
        if not math.isfinite(innovation):
            return self._reject("PROPID_ERR_NUMERIC")
        idx = np.flatnonzero(h)
        scale = len(idx) * float(np.sum(h[idx] ** 2 * np.diag(self.cov)[idx]))
        cov_h = self.cov @ h
        innovation_var = float(h @ cov_h) + self.accel_var
        if not (innovation_var >= self.accel_var - ROUNDING_TOL * scale):
            if self._repair():
                self.health |= HEALTH["COV_REPAIRED"]
                self.counters_data["cov_repairs"] += 1
            cov_h = self.cov @ h
            innovation_var = float(h @ cov_h) + self.accel_var
        innovation_var = max(innovation_var, self.accel_var)
        loaded_noise = self.update_loading * (innovation_var - self.accel_var)  # C: propid_scalar_update
        if loaded_noise > self.accel_var:
            innovation_var += loaded_noise - self.accel_var
        self.accel_innovation = innovation
        self.accel_innovation_test_ratio = innovation * innovation / innovation_var * self.inv_gate_sq
        self.accel_time_us = int(t_us)
        self.has_accel = True
        self.counters_data["accel_accepted"] += 1
        if self.gate_sq > 0.0 and innovation * innovation > self.gate_sq * innovation_var:
            if self.accel_gated_run < self.gate_max_consecutive:
                self.accel_gated_run += 1
                self.counters_data["accel_gated"] += 1
                return STATUS["PROPID_OK_GATED"]
            self.state[b] = f[2] - thrust
            self._reset_state(b)
            cov_h = self.cov @ h
            innovation_var = max(float(h @ cov_h) + self.accel_var, self.accel_var)
            loaded_noise = self.update_loading * (innovation_var - self.accel_var)
            if loaded_noise > self.accel_var:
                innovation_var += loaded_noise - self.accel_var
            innovation = 0.0
            self.counters_data["accel_reanchored"] += 1
        self.accel_gated_run = 0
        self._fuse(cov_h, innovation, innovation_var)
        self._clamp()
        return STATUS["PROPID_OK"]

    def _clamp(self, extra: int = 0) -> None:
        lo, hi = self.c["coeff_rel_min"], self.c["coeff_rel_max"]
        clamped = extra
        # C: propid_clamp_coefficients, in index order, per rotor: the state mapped out of the
        # kept bases and back, each projection with P's column per rotor (P kept).
        coeffs = self._per_rotor_state()[3:self.first_bias]
        if np.any(coeffs < lo) or np.any(coeffs > hi):
            state = self._per_rotor_state()
            cov = self._per_rotor_cov()
            for k in range(3, self.first_bias):
                if state[k] < lo:
                    self._project(state, cov[:, k], k, lo)
                    clamped += 1
                elif state[k] > hi:
                    self._project(state, cov[:, k], k, hi)
                    clamped += 1
            if clamped > extra:
                state[3:self.first_bias] = np.clip(state[3:self.first_bias], lo, hi)
            self.state = self.basis @ state
        if self.torque_scale is not None:  # C: propid_clamp_torque_scale (r = 1/s, s in [lo, hi])
            s, r_lo, r_hi = self.torque_scale, _f32(1.0 / _f32(hi)), _f32(1.0 / _f32(lo))
            clamped += int(not r_lo <= self.state[s] <= r_hi)
            self.state[s] = min(max(self.state[s], r_lo), r_hi)
        if clamped:
            self.health |= HEALTH["STATE_CLAMPED"]
            self.counters_data["state_clamps"] += clamped

    @staticmethod
    def _project(state: np.ndarray, column: np.ndarray, k: int, bound: float) -> None:
        """C: propid_project_onto_bound. The estimate (in place) moved to the mean of N(x, P)
        given state k = bound, P unchanged (docs/math.md §15); `column` is P's column k in
        the state's basis."""
        pkk = float(column[k])
        shift = bound - float(state[k])
        if not (pkk > 0.0 and math.isfinite(pkk) and math.isfinite(shift)):
            state[k] = bound
            return
        state += column * (shift / pkk)
        state[k] = bound

    # ------------------------------------------------------------------ outputs
    def estimate(self) -> Estimate:
        n_rot = self.rotor_count
        state, cov = self.scaled_state()  # per rotor
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        kf = slice(3, 3 + n_rot)
        km = slice(self.first_drag, self.first_drag + n_rot)
        bias = slice(self.first_bias, self.first_bias + 3)
        var = np.diag(cov)
        kf_value = state[kf].copy()
        if self.torque_scale is not None:
            # C: kf = r g, its variance to first order; s = 1/r
            r = self.torque_scale
            g = state[kf]
            kf_value = state[r] * g
            var = var.copy()
            var[kf] = state[r] ** 2 * var[kf] + g * g * cov[r, r] + 2.0 * state[r] * g * cov[kf, r]
            std = std.copy()
            std[kf] = np.sqrt(np.maximum(var[kf], 0.0))
        bits = 1 << np.arange(n_rot)

        def mask(condition: np.ndarray) -> int:
            return int(np.sum(bits[condition]))

        # C (propid_estimate.c): converged when 3 std (inertia's included) < converged_rel_std;
        # the C filter also asks its consistency monitor to vouch, which this reference does not have.
        kf_converged = mask(var[kf] < self.claim_var[0])
        km_converged = mask(var[km] < self.claim_var[1])
        health = self.health
        if not self.has_rotor_data:
            health |= HEALTH["NO_ROTOR_DATA"]
        if self.counters_data["rejected"][-STATUS["PROPID_ERR_ROTOR_STALE"]] != self.stale_mark:
            health |= HEALTH["ROTOR_STALE"]
        all_rotors = (1 << n_rot) - 1
        if kf_converged == all_rotors and km_converged == all_rotors:
            health |= HEALTH["ALL_CONVERGED"]
        return Estimate(
            time_us=self.time_us,
            body_rate=state[:3].copy(), body_rate_std=std[:3].copy(),
            thrust_coeff=kf_value * self.kf_nominal, thrust_coeff_std=std[kf] * self.kf_nominal,
            drag_coeff=state[km] * self.km_nominal, drag_coeff_std=std[km] * self.km_nominal,
            gyro_bias=state[bias].copy(), gyro_bias_std=std[bias].copy(),
            innovation=self.innovation.copy(), innovation_test_ratio=self.innovation_test_ratio.copy(),
            thrust_coeff_converging=mask(var[kf] < 0.25 * self.prior_var[kf]),
            thrust_coeff_converged=kf_converged,
            drag_coeff_converging=mask(var[km] < 0.25 * self.prior_var[km]),
            drag_coeff_converged=km_converged,
            health=health, health_flags=health_names(health),
            **self._optional_estimates(std),
        )

    def _optional_estimates(self, std: np.ndarray) -> dict:
        out: dict = {}
        if self.first_disturbance is not None:
            d = slice(self.first_disturbance, self.first_disturbance + 3)
            out["disturbance_torque"] = self.inertia @ self.state[d]
            out["disturbance_torque_std"] = np.sqrt((self.inertia ** 2) @ (std[d] ** 2))
        if self.torque_scale is not None:  # s = 1/r
            r = float(self.state[self.torque_scale])
            out["torque_scale"] = 1.0 / r
            out["torque_scale_std"] = float(std[self.torque_scale]) / (r * r)
        if self.accel_bias is not None:
            out["accel_bias"] = float(self.state[self.accel_bias])
            out["accel_bias_std"] = float(std[self.accel_bias])
            out["accel_innovation"] = float(self.accel_innovation)
            out["accel_innovation_test_ratio"] = float(self.accel_innovation_test_ratio)
        out["rotor_delay_us"] = self.rotor_delay_us
        out["model_terms"] = ((MODEL_TERMS["DISTURBANCE"] if self.first_disturbance is not None else 0)
                              | (MODEL_TERMS["ACCEL"] if self.accel_bias is not None else 0)
                              | (MODEL_TERMS["TORQUE_SCALE"] if self.torque_scale is not None else 0)
                              | (MODEL_TERMS["ROTOR_INERTIA"] if self.rotor_inertia_on else 0)
                              | (MODEL_TERMS["AERO_DAMPING"] if self.aero_damping_on else 0)
                              | (MODEL_TERMS["ESC_DELAY"] if self.rotor_delay_us else 0))
        return out

    def counters(self) -> dict:
        d = dict(self.counters_data)
        d["axis_gated"] = list(d["axis_gated"])
        d["rejected"] = {name: d["rejected"][-code] for name, code in STATUS.items()
                         if code < 0 and d["rejected"][-code]}
        return d

    def scaled_state(self) -> tuple[np.ndarray, np.ndarray]:
        """(state, P) per rotor (C: propid_abi_copy_state maps the coefficient blocks back too)."""
        return self._per_rotor_state(), self._per_rotor_cov()

    @staticmethod
    def status_name(code: int) -> str:
        from propid.cfilter import STATUS_NAME
        return STATUS_NAME.get(int(code), f"PROPID_UNKNOWN_STATUS({int(code)})")


def thrust_torque_basis(roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Q of the kf block (C: propid_config.c, thrust_basis_from_torques, docs/math.md §2): Q = H_1 H_0, H_0 the
    reflection whose first row is the roll-torque direction (up to sign), H_1 on elements
    1..N-1 making the second row the pitch-torque direction orthogonalised against it; a
    direction that vanishes (or is parallel to the roll one) leaves its reflection out."""
    n = roll.size
    size = [float(roll @ roll), float(pitch @ pitch)]
    reflections = []
    r_hat = None
    for k, d in enumerate((np.array(roll, dtype=float), np.array(pitch, dtype=float))):
        if k >= n:
            break
        if k == 1 and r_hat is not None:
            d = d - (d @ r_hat) * r_hat
            d = reflections[0] @ d
            d[0] = 0.0
        norm_sq = float(d[k:] @ d[k:])
        if not (norm_sq > 1.0e-6 * size[k]) or not math.isfinite(norm_sq):
            reflections.append(np.eye(n))
            continue
        d = d / math.sqrt(norm_sq)
        if k == 0:
            r_hat = d.copy()
        v = np.zeros(n)
        v[k:] = d[k:]
        v[k] += 1.0 if d[k] >= 0.0 else -1.0
        reflections.append(np.eye(n) - 2.0 * np.outer(v, v) / float(v @ v))
    q = np.eye(n)
    for h in reflections:
        q = h @ q
    return q


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
