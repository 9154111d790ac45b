"""ctypes binding of the C filter (build/host/firmware/libpropid_shared.so).

The same C code that flies on the MCU, driven from Python::

    from propid.cfilter import CFilter, FilterConfig
    config = FilterConfig.from_vehicle(read_vehicle(path), gyro_sample_rate_hz=500.0)
    f = CFilter(config)
    f.push_rotor_speeds(t_us, speeds_rad_s)      # -> status code (int)
    status = f.push_gyro(t_us, gyro_rad_s)      # -> status code (int)
    est = f.estimate()                          # Estimate, SI units, numpy arrays
    if status < 0: print(CFilter.status_name(status))

Where the library comes from (first that applies):
  1. env PROPID_LIBRARY (full path of the .so),
  2. $PROPID_BUILD_DIR/firmware/libpropid_shared.so,
  3. <repo>/build/host/firmware/libpropid_shared.so.
The library's struct sizes (propid_abi.c) are checked against this module's
ctypes layout at load time, so a stale or differently configured build fails
loudly instead of corrupting memory.

FilterConfig is plain Python (no library needed) and is shared with the
float64 reference filter (propid.reference_filter).
"""

from __future__ import annotations

import ctypes
import math
import os
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional, Sequence

import numpy as np

from propid.errors import UserError

if TYPE_CHECKING:
    from propid.flightlog import Vehicle

# Compile-time limit the layout below is built for (propid_config.h default).
MAX_ROTORS = 8
RATE_STATES = 3
BIAS_STATES = 3
DISTURBANCE_STATES = 3
ACCEL_BIAS_STATES = 1
TORQUE_SCALE_STATES = 1
MAX_STATES = (RATE_STATES + 2 * MAX_ROTORS + BIAS_STATES + DISTURBANCE_STATES + ACCEL_BIAS_STATES
              + TORQUE_SCALE_STATES)
REJECT_SLOTS = 16
# Telemetry-delay buffer capacity (propid_config.h PROPID_DELAY_SLOTS default; checked at load).
DELAY_SLOTS = 32

# propid_status_t (propid.h). Negative = rejected, filter state unchanged.
STATUS = {
    "PROPID_OK": 0,
    "PROPID_OK_GATED": 1,
    "PROPID_OK_QUEUED": 2,
    "PROPID_ERR_NULL": -1,
    "PROPID_ERR_NOT_INITIALISED": -2,
    "PROPID_ERR_CONFIG": -3,
    "PROPID_ERR_NOT_FINITE": -4,
    "PROPID_ERR_ROTOR_SPEED_NEGATIVE": -5,
    "PROPID_ERR_ROTOR_SPEED_RANGE": -6,
    "PROPID_ERR_ROTOR_COUNT": -7,
    "PROPID_ERR_ROTOR_INDEX": -8,
    "PROPID_ERR_GYRO_RANGE": -9,
    "PROPID_ERR_TIME_BACKWARDS": -10,
    "PROPID_ERR_TIME_JUMP": -11,
    "PROPID_ERR_NO_ROTOR_DATA": -12,
    "PROPID_ERR_ROTOR_STALE": -13,
    "PROPID_ERR_NUMERIC": -14,
    "PROPID_ERR_ACCEL_RANGE": -15,
}
STATUS_NAME = {code: name for name, code in STATUS.items()}
globals().update(STATUS)  # PROPID_OK, PROPID_ERR_TIME_JUMP, ... as module constants

# Health flags (propid_estimate_t.health).
HEALTH = {
    "NO_ROTOR_DATA": 1 << 0,
    "ROTOR_STALE": 1 << 1,
    "GATED": 1 << 2,
    "COV_REPAIRED": 1 << 3,
    "STATE_CLAMPED": 1 << 4,
    "GATE_REOPENED": 1 << 5,
    "ALL_CONVERGED": 1 << 6,
    "TIME_RESYNCED": 1 << 7,
    "ROTOR_DAMAGE": 1 << 8,
    "MODEL_MISMATCH": 1 << 9,
}


# propid_estimate_t.model_terms (PROPID_TERM_*).
MODEL_TERMS = {
    "DISTURBANCE": 1 << 0,
    "ACCEL": 1 << 1,
    "TORQUE_SCALE": 1 << 2,
    "ROTOR_INERTIA": 1 << 3,
    "ESC_DELAY": 1 << 4,
    "AERO_DAMPING": 1 << 5,
}


def health_names(health: int) -> list[str]:
    """Names of the flags set in a health word, e.g. ['GATED', 'COV_REPAIRED']."""
    return [name for name, bit in HEALTH.items() if health & bit]


# ---------------------------------------------------------------------------
# ctypes mirrors of the public structs (propid.h). Keep in the same order.
# ---------------------------------------------------------------------------
class RotorConfigStruct(ctypes.Structure):
    _fields_ = [
        ("position_m", ctypes.c_float * 3),
        ("yaw_sign", ctypes.c_float),
        ("thrust_coeff_nominal", ctypes.c_float),
        ("drag_coeff_nominal", ctypes.c_float),
    ]


# Tuning fields of propid_config_t after the geometry, in struct order, with their C type.
_TUNING_FIELDS = [
    ("rate_std0", ctypes.c_float),
    ("thrust_coeff_rel_std0", ctypes.c_float),
    ("drag_coeff_rel_std0", ctypes.c_float),
    ("gyro_bias_std0", ctypes.c_float),
    ("gyro_noise_density", ctypes.c_float),
    ("gyro_sample_rate_hz", ctypes.c_float),
    ("rate_process_noise", ctypes.c_float),
    ("thrust_coeff_rel_walk", ctypes.c_float),
    ("drag_coeff_rel_walk", ctypes.c_float),
    ("gyro_bias_walk", ctypes.c_float),
    ("gate_sigma", ctypes.c_float),
    ("gate_max_consecutive", ctypes.c_uint16),
    ("gyro_stuck_samples", ctypes.c_uint16),
    ("max_rotor_speed", ctypes.c_float),
    ("gyro_range", ctypes.c_float),
    ("rotor_stale_us", ctypes.c_uint32),
    ("max_gyro_gap_us", ctypes.c_uint32),
    ("coeff_rel_min", ctypes.c_float),
    ("coeff_rel_max", ctypes.c_float),
    ("converged_rel_std", ctypes.c_float),
]
# The optional terms after them (propid_config_t, same order): rotor_inertia[] first.
_OPTIONAL_FIELDS = [
    ("disturbance_torque", ctypes.c_uint8),
    ("disturbance_std0", ctypes.c_float),
    ("disturbance_walk", ctypes.c_float),
    ("disturbance_bandwidth", ctypes.c_float),
    ("mass", ctypes.c_float),
    ("accel_noise_std", ctypes.c_float),
    ("accel_bias_std0", ctypes.c_float),
    ("accel_bias_walk", ctypes.c_float),
    ("accel_range", ctypes.c_float),
    ("torque_scale", ctypes.c_uint8),
    ("torque_scale_std0", ctypes.c_float),
    ("torque_scale_walk", ctypes.c_float),
    ("rotor_delay_us", ctypes.c_int32),
    ("rotor_speed_noise", ctypes.c_float),
    ("rotor_speed_noise_time", ctypes.c_float),
    ("inertia_rel_std", ctypes.c_float),
    ("motor_time_constant", ctypes.c_float),
    ("input_error_compensation", ctypes.c_uint8),
    ("motor_command_instrument", ctypes.c_uint8),
    ("rotor_speed_noise_hold", ctypes.c_uint8),
    ("rotor_speed_noise_split", ctypes.c_uint8),
    ("motor_command_lag", ctypes.c_float),
    ("motor_command_memory", ctypes.c_float),
    ("motor_command_min_f", ctypes.c_float),
]
# After aero_damping[3] (propid_config_t's last fields).
_LAST_FIELDS = [
    ("accel_error_std", ctypes.c_float),
    ("accel_error_time", ctypes.c_float),
    ("rotor_timing_error", ctypes.c_float),
]
_INTEGER_TYPES = (ctypes.c_uint8, ctypes.c_uint16, ctypes.c_uint32, ctypes.c_int32)


def _config_struct(max_rotors: int) -> type:
    """propid_config_t of a build with PROPID_MAX_ROTORS = max_rotors."""
    return type(f"ConfigStruct{max_rotors}", (ctypes.Structure,), {"_fields_": [
        ("rotor_count", ctypes.c_uint8),
        ("rotor", RotorConfigStruct * max_rotors),
        ("inertia", (ctypes.c_float * 3) * 3),
    ] + _TUNING_FIELDS + [("rotor_inertia", ctypes.c_float * max_rotors)] + _OPTIONAL_FIELDS
        + [("aero_damping", ctypes.c_float * 3)] + _LAST_FIELDS})


def _estimate_struct(max_rotors: int) -> type:
    """propid_estimate_t of a build with PROPID_MAX_ROTORS = max_rotors."""
    return type(f"EstimateStruct{max_rotors}", (ctypes.Structure,), {"_fields_": [
        ("time_us", ctypes.c_uint64),
        ("rotor_count", ctypes.c_uint8),
        ("body_rate", ctypes.c_float * 3),
        ("body_rate_std", ctypes.c_float * 3),
        ("thrust_coeff", ctypes.c_float * max_rotors),
        ("thrust_coeff_std", ctypes.c_float * max_rotors),
        ("drag_coeff", ctypes.c_float * max_rotors),
        ("drag_coeff_std", ctypes.c_float * max_rotors),
        ("gyro_bias", ctypes.c_float * 3),
        ("gyro_bias_std", ctypes.c_float * 3),
        ("innovation", ctypes.c_float * 3),
        ("innovation_test_ratio", ctypes.c_float * 3),
        ("thrust_coeff_converging", ctypes.c_uint16),
        ("thrust_coeff_converged", ctypes.c_uint16),
        ("drag_coeff_converging", ctypes.c_uint16),
        ("drag_coeff_converged", ctypes.c_uint16),
        ("health", ctypes.c_uint32),
        ("disturbance_torque", ctypes.c_float * 3),
        ("disturbance_torque_std", ctypes.c_float * 3),
        ("accel_bias", ctypes.c_float),
        ("accel_bias_std", ctypes.c_float),
        ("accel_innovation", ctypes.c_float),
        ("accel_innovation_test_ratio", ctypes.c_float),
        ("torque_scale", ctypes.c_float),
        ("torque_scale_std", ctypes.c_float),
        ("rotor_delay_us", ctypes.c_int32),
        ("model_terms", ctypes.c_uint8),
    ]})


# The default build (PROPID_MAX_ROTORS = 8); a quad build's library gets its own
# (struct_types(), load_library).
ConfigStruct = _config_struct(MAX_ROTORS)
EstimateStruct = _estimate_struct(MAX_ROTORS)
_STRUCTS: dict[int, tuple[type, type]] = {MAX_ROTORS: (ConfigStruct, EstimateStruct)}


def struct_types(max_rotors: int) -> tuple[type, type]:
    """(ConfigStruct, EstimateStruct) for a build's PROPID_MAX_ROTORS."""
    if max_rotors not in _STRUCTS:
        _STRUCTS[max_rotors] = (_config_struct(max_rotors), _estimate_struct(max_rotors))
    return _STRUCTS[max_rotors]


class CountersStruct(ctypes.Structure):
    _fields_ = [
        ("gyro_accepted", ctypes.c_uint32),
        ("rotor_accepted", ctypes.c_uint32),
        ("axis_gated", ctypes.c_uint32 * 3),
        ("gate_reopened", ctypes.c_uint32),
        ("cov_repairs", ctypes.c_uint32),
        ("state_clamps", ctypes.c_uint32),
        ("resyncs", ctypes.c_uint32),
        ("rejected", ctypes.c_uint32 * REJECT_SLOTS),
        ("accel_accepted", ctypes.c_uint32),
        ("accel_gated", ctypes.c_uint32),
        ("accel_reanchored", ctypes.c_uint32),
        ("delay_overflows", ctypes.c_uint32),
        ("model_mismatch", ctypes.c_uint32),
        ("gyro_stuck", ctypes.c_uint32),
    ]


# ---------------------------------------------------------------------------
# Configuration (pure Python, shared with the reference filter)
# ---------------------------------------------------------------------------
# Mirror of propid_config_default() (firmware/src/propid_config.c; reasons in
# docs/design.md). tests/host_tools/test_reference_vs_c.py checks they agree.
DEFAULT_TUNING: dict[str, float | int] = {
    "rate_std0": 1.0,
    "thrust_coeff_rel_std0": 0.3,
    "drag_coeff_rel_std0": 0.3,
    "gyro_bias_std0": 0.05,
    "gyro_noise_density": 5.0e-4,
    "gyro_sample_rate_hz": 500.0,
    "rate_process_noise": 0.2,
    "thrust_coeff_rel_walk": 0.02,
    "drag_coeff_rel_walk": 0.02,
    "gyro_bias_walk": 1.0e-4,
    "gate_sigma": 5.0,
    "gate_max_consecutive": 25,
    "gyro_stuck_samples": 0,
    "max_rotor_speed": 6000.0,
    "gyro_range": 34.0,
    "rotor_stale_us": 50000,
    "max_gyro_gap_us": 50000,
    "coeff_rel_min": 0.05,
    "coeff_rel_max": 5.0,
    "converged_rel_std": 0.05,
    # Optional terms (off: disturbance_torque 0, mass 0; docs/math.md §7-9).
    "disturbance_torque": 0,
    "disturbance_std0": 20.0,
    "disturbance_walk": 0.2,
    "disturbance_bandwidth": 0.0,
    "mass": 0.0,
    "accel_noise_std": 0.5,
    "accel_bias_std0": 0.5,
    "accel_bias_walk": 1.0e-3,
    "accel_range": 160.0,
    "torque_scale": 0,
    "torque_scale_std0": 0.5,
    "torque_scale_walk": 0.0,
    # Telemetry delay (docs/math.md §12): > 0 rotor speeds lag the gyro, < 0 the gyro lags.
    "rotor_delay_us": 0,
    # Rotor-speed input error (docs/math.md §14): std [rad/s] and correlation time [s]; 0: off.
    "rotor_speed_noise": 0.0,
    "rotor_speed_noise_time": 0.0,
    # Relative std of the configured inertia's scale: counted by converged claims (0: J exact).
    "inertia_rel_std": 0.0,
    # Motor time constant [s]: bounds how fast a true rotor speed can change (slew test).
    "motor_time_constant": 0.01,
    # Errors-in-variables compensation of the coefficient update (needs rotor_speed_noise > 0).
    "input_error_compensation": 0,
    # The motor commands as the rotor input's instrument (docs/math.md §16): on/off, the first
    # stage's lag [s] and memory [s], and its weak-instrument guard (least F statistic; 0: none).
    "motor_command_instrument": 0,
    "motor_command_lag": 0.03,
    "motor_command_memory": 10.0,
    "motor_command_min_f": 0.0,
    # The accelerometer row's slow model error as a Gauss-Markov state (docs/math.md §9): std, time; 0: off.
    "accel_error_std": 0.0,
    "accel_error_time": 0.0,
    # The input error's correlation time per rotor from how long its value has stood
    # (docs/math.md §14; needs rotor_speed_noise > 0, the configured time its ceiling).
    "rotor_speed_noise_hold": 0,
    # 1: the input error is a truncation's, rotor_speed_noise its RMS q / sqrt(3): mean q / 2
    # common to every rotor, spread q / sqrt(12) per rotor (docs/math.md §14). 0: independent.
    "rotor_speed_noise_split": 0,
    # Std of a rotor report's age error [s], common to the rotors of a report: the step's input is off by
    # that time x du/dt while the speeds change (docs/math.md §14, "The report's timing"). 0: off.
    "rotor_timing_error": 0.0,
}


@dataclass
class FilterConfig:
    """Everything propid_config_t holds, in SI units, for N rotors.

    positions: N x 3 rotor hub positions in body FLU [m]; yaw_signs: N of +-1;
    thrust_coeff_nominal / drag_coeff_nominal: N values; inertia: 3 x 3 [kg m^2].
    The tuning fields have the C names and the C defaults (docs/design.md §8).
    Set gyro_sample_rate_hz to the gyro rate of your data; for real vehicles set
    rate_process_noise to 2-10 (the default 0.2 suits the simulator; §12).
    """

    positions: list
    yaw_signs: list
    thrust_coeff_nominal: list
    drag_coeff_nominal: list
    inertia: list
    rate_std0: float = DEFAULT_TUNING["rate_std0"]
    thrust_coeff_rel_std0: float = DEFAULT_TUNING["thrust_coeff_rel_std0"]
    drag_coeff_rel_std0: float = DEFAULT_TUNING["drag_coeff_rel_std0"]
    gyro_bias_std0: float = DEFAULT_TUNING["gyro_bias_std0"]
    gyro_noise_density: float = DEFAULT_TUNING["gyro_noise_density"]
    gyro_sample_rate_hz: float = DEFAULT_TUNING["gyro_sample_rate_hz"]
    rate_process_noise: float = DEFAULT_TUNING["rate_process_noise"]
    thrust_coeff_rel_walk: float = DEFAULT_TUNING["thrust_coeff_rel_walk"]
    drag_coeff_rel_walk: float = DEFAULT_TUNING["drag_coeff_rel_walk"]
    gyro_bias_walk: float = DEFAULT_TUNING["gyro_bias_walk"]
    gate_sigma: float = DEFAULT_TUNING["gate_sigma"]
    gate_max_consecutive: int = DEFAULT_TUNING["gate_max_consecutive"]
    gyro_stuck_samples: int = DEFAULT_TUNING["gyro_stuck_samples"]
    max_rotor_speed: float = DEFAULT_TUNING["max_rotor_speed"]
    gyro_range: float = DEFAULT_TUNING["gyro_range"]
    rotor_stale_us: int = DEFAULT_TUNING["rotor_stale_us"]
    max_gyro_gap_us: int = DEFAULT_TUNING["max_gyro_gap_us"]
    coeff_rel_min: float = DEFAULT_TUNING["coeff_rel_min"]
    coeff_rel_max: float = DEFAULT_TUNING["coeff_rel_max"]
    converged_rel_std: float = DEFAULT_TUNING["converged_rel_std"]
    rotor_inertia: Optional[list] = None  # per rotor [kg m^2]; None or zeros: not modelled
    disturbance_torque: int = DEFAULT_TUNING["disturbance_torque"]
    disturbance_std0: float = DEFAULT_TUNING["disturbance_std0"]
    disturbance_walk: float = DEFAULT_TUNING["disturbance_walk"]
    disturbance_bandwidth: float = DEFAULT_TUNING["disturbance_bandwidth"]
    mass: float = DEFAULT_TUNING["mass"]
    accel_noise_std: float = DEFAULT_TUNING["accel_noise_std"]
    accel_bias_std0: float = DEFAULT_TUNING["accel_bias_std0"]
    accel_bias_walk: float = DEFAULT_TUNING["accel_bias_walk"]
    accel_range: float = DEFAULT_TUNING["accel_range"]
    torque_scale: int = DEFAULT_TUNING["torque_scale"]
    torque_scale_std0: float = DEFAULT_TUNING["torque_scale_std0"]
    torque_scale_walk: float = DEFAULT_TUNING["torque_scale_walk"]
    rotor_delay_us: int = DEFAULT_TUNING["rotor_delay_us"]
    rotor_speed_noise: float = DEFAULT_TUNING["rotor_speed_noise"]
    rotor_speed_noise_time: float = DEFAULT_TUNING["rotor_speed_noise_time"]
    inertia_rel_std: float = DEFAULT_TUNING["inertia_rel_std"]
    motor_time_constant: float = DEFAULT_TUNING["motor_time_constant"]
    input_error_compensation: int = DEFAULT_TUNING["input_error_compensation"]
    motor_command_instrument: int = DEFAULT_TUNING["motor_command_instrument"]
    motor_command_lag: float = DEFAULT_TUNING["motor_command_lag"]
    motor_command_memory: float = DEFAULT_TUNING["motor_command_memory"]
    motor_command_min_f: float = DEFAULT_TUNING["motor_command_min_f"]
    accel_error_std: float = DEFAULT_TUNING["accel_error_std"]
    accel_error_time: float = DEFAULT_TUNING["accel_error_time"]
    rotor_speed_noise_hold: int = DEFAULT_TUNING["rotor_speed_noise_hold"]
    rotor_speed_noise_split: int = DEFAULT_TUNING["rotor_speed_noise_split"]
    rotor_timing_error: float = DEFAULT_TUNING["rotor_timing_error"]
    # Known aerodynamic rate damping [N m s/rad] per body axis (body torque -d_a omega_a, docs/math.md §17);
    # None or zeros: not modelled.
    aero_damping: Optional[list] = None

    @property
    def rotor_count(self) -> int:
        return len(self.positions)

    @property
    def state_count(self) -> int:
        return (6 + 2 * self.rotor_count + (DISTURBANCE_STATES if self.disturbance_torque else 0)
                + (ACCEL_BIAS_STATES if self.mass > 0.0 else 0)
                + (TORQUE_SCALE_STATES if self.torque_scale else 0))

    def with_overrides(self, **overrides: Any) -> "FilterConfig":
        """A copy with some tuning fields changed (unknown names raise UserError)."""
        names = {f.name for f in fields(self)}
        unknown = sorted(set(overrides) - names)
        if unknown:
            raise UserError(f"unknown filter setting(s): {', '.join(unknown)}")
        return replace(self, **overrides)

    @classmethod
    def symmetric(cls, rotor_count: int, arm_m: float, first_angle_rad: float,
                  first_yaw_sign: float, thrust_coeff_nominal: float,
                  drag_coeff_nominal: float, inertia: Sequence, **overrides: Any) -> "FilterConfig":
        """Rotors evenly on a circle (same convention as propid_config_set_symmetric)."""
        positions, yaw_signs = [], []
        for i in range(rotor_count):
            angle = first_angle_rad + 2.0 * math.pi * i / rotor_count
            positions.append([arm_m * math.cos(angle), arm_m * math.sin(angle), 0.0])
            yaw_signs.append(first_yaw_sign if i % 2 == 0 else -first_yaw_sign)
        config = cls(positions, yaw_signs, [thrust_coeff_nominal] * rotor_count,
                     [drag_coeff_nominal] * rotor_count, _inertia_matrix(inertia))
        return config.with_overrides(**overrides)

    @classmethod
    def from_vehicle(cls, vehicle: Vehicle, **overrides: Any) -> "FilterConfig":
        """From a parsed vehicle (propid.flightlog.Vehicle, read by read_vehicle: the one
        reader of the vehicle file, docs/flightlog.md)."""
        name = vehicle.name or "vehicle"
        if vehicle.rotor_count > MAX_ROTORS:
            raise UserError(f"{name}: {vehicle.rotor_count} rotors, the filter is built for at most {MAX_ROTORS}")
        if vehicle.inertia is None:
            raise UserError(f"{name}: 'inertia' is null; the filter needs the body inertia")
        for key, values in (("kf_nominal", vehicle.kf_nominal), ("km_nominal", vehicle.km_nominal)):
            if values is None:
                raise UserError(f"{name}: '{key}' is null; the filter needs a nominal value "
                                f"(a catalogue or thrust-stand figure) to scale its estimate")
            if len(values) != vehicle.rotor_count:
                raise UserError(f"{name}: '{key}' has {len(values)} values for {vehicle.rotor_count} rotors")
            if not all(math.isfinite(v) and v > 0.0 for v in values):
                raise UserError(f"{name}: '{key}' must be positive")
        positions = [[float(v) for v in rotor.position] for rotor in vehicle.rotors]
        yaw_signs = [float(rotor.yaw_sign) for rotor in vehicle.rotors]
        inertia = _inertia_matrix(vehicle.inertia, name)
        return cls(positions, yaw_signs, [float(v) for v in vehicle.kf_nominal],
                   [float(v) for v in vehicle.km_nominal], inertia).with_overrides(**overrides)

    def to_struct(self, max_rotors: int = MAX_ROTORS) -> ConfigStruct:
        if not 1 <= self.rotor_count <= max_rotors:
            raise UserError(f"rotor count {self.rotor_count} outside 1..{max_rotors}")
        s = struct_types(max_rotors)[0]()
        s.rotor_count = self.rotor_count
        for i in range(self.rotor_count):
            r = s.rotor[i]
            for a in range(3):
                r.position_m[a] = float(self.positions[i][a])
            r.yaw_sign = float(self.yaw_signs[i])
            r.thrust_coeff_nominal = float(self.thrust_coeff_nominal[i])
            r.drag_coeff_nominal = float(self.drag_coeff_nominal[i])
        for a in range(3):
            for b in range(3):
                s.inertia[a][b] = float(self.inertia[a][b])
        for name, ctype in _TUNING_FIELDS + _OPTIONAL_FIELDS + _LAST_FIELDS:
            value = getattr(self, name)
            setattr(s, name, int(value) if ctype in _INTEGER_TYPES else float(value))
        if self.rotor_inertia is not None:
            if len(self.rotor_inertia) != self.rotor_count:
                raise UserError(f"rotor_inertia has {len(self.rotor_inertia)} values for {self.rotor_count} rotors")
            for i, value in enumerate(self.rotor_inertia):
                s.rotor_inertia[i] = float(value)
        if self.aero_damping is not None:
            if len(self.aero_damping) != 3:
                raise UserError(f"aero_damping has {len(self.aero_damping)} values, needs 3 (x, y, z)")
            for a, value in enumerate(self.aero_damping):
                s.aero_damping[a] = float(value)
        return s


def _inertia_matrix(inertia: Any, name: str = "vehicle") -> list:
    values = np.asarray(inertia, dtype=float)
    if values.shape == (3,):
        return np.diag(values).tolist()
    if values.shape == (9,):
        return values.reshape(3, 3).tolist()
    if values.shape == (3, 3):
        return values.tolist()
    raise UserError(f"{name}: 'inertia' must be [Jxx, Jyy, Jzz] or a 3x3 matrix")


# ---------------------------------------------------------------------------
# Results
# ---------------------------------------------------------------------------
@dataclass
class Estimate:
    """propid_estimate_t in SI units (arrays sized to the rotor count)."""

    time_us: int
    body_rate: np.ndarray
    body_rate_std: np.ndarray
    thrust_coeff: np.ndarray
    thrust_coeff_std: np.ndarray
    drag_coeff: np.ndarray
    drag_coeff_std: np.ndarray
    gyro_bias: np.ndarray
    gyro_bias_std: np.ndarray
    innovation: np.ndarray
    innovation_test_ratio: np.ndarray
    thrust_coeff_converging: int
    thrust_coeff_converged: int
    drag_coeff_converging: int
    drag_coeff_converged: int
    health: int
    health_flags: list = field(default_factory=list)
    disturbance_torque: np.ndarray = field(default_factory=lambda: np.zeros(3))
    disturbance_torque_std: np.ndarray = field(default_factory=lambda: np.zeros(3))
    accel_bias: float = 0.0
    accel_bias_std: float = 0.0
    accel_innovation: float = 0.0
    accel_innovation_test_ratio: float = 0.0
    torque_scale: float = 1.0
    torque_scale_std: float = 0.0
    rotor_delay_us: int = 0
    model_terms: int = 0  # MODEL_TERMS bits: the optional terms configured


# ---------------------------------------------------------------------------
# Library loading
# ---------------------------------------------------------------------------
_LIBRARY_NAME = "libpropid_shared.so"


def library_path() -> Path:
    """Where the shared library is looked for (see the module docstring)."""
    explicit = os.environ.get("PROPID_LIBRARY")
    if explicit:
        return Path(explicit)
    build_dir = os.environ.get("PROPID_BUILD_DIR")
    if build_dir:
        return Path(build_dir) / "firmware" / _LIBRARY_NAME
    repo = Path(__file__).resolve().parents[2]
    return repo / "build" / "host" / "firmware" / _LIBRARY_NAME


_loaded: dict[str, ctypes.CDLL] = {}


def load_library(path: Optional[os.PathLike] = None) -> ctypes.CDLL:
    """Load (once) and ABI-check the shared library; UserError if missing or mismatched."""
    lib_path = Path(path) if path is not None else library_path()
    key = str(lib_path.resolve()) if lib_path.exists() else str(lib_path)
    if key in _loaded:
        return _loaded[key]
    if not lib_path.exists():
        raise UserError(f"C filter library not found at {lib_path}: build it with `make host` "
                        f"(cmake target propid_shared) or set PROPID_LIBRARY / PROPID_BUILD_DIR")
    try:
        lib = ctypes.CDLL(str(lib_path))
    except OSError as exc:
        raise UserError(f"cannot load C filter library {lib_path}: {exc}") from exc
    lib.propid_abi_max_rotors.restype = ctypes.c_uint32
    lib.propid_abi_max_rotors.argtypes = []
    max_rotors = int(lib.propid_abi_max_rotors())
    if not 1 <= max_rotors <= 16:
        raise UserError(f"{lib_path}: PROPID_MAX_ROTORS = {max_rotors} is not a propid build")
    lib.propid_max_rotors = max_rotors
    # The state-vector capacity (smaller in a build with optional blocks compiled out).
    if hasattr(lib, "propid_abi_max_states"):
        lib.propid_abi_max_states.restype = ctypes.c_uint32
        lib.propid_abi_max_states.argtypes = []
        lib.propid_max_states = int(lib.propid_abi_max_states())
    else:
        lib.propid_max_states = MAX_STATES
    lib.propid_structs = struct_types(max_rotors)
    _declare(lib)
    _check_abi(lib, lib_path)
    _loaded[key] = lib
    return lib


def _declare(lib: ctypes.CDLL) -> None:
    ConfigStruct, EstimateStruct = lib.propid_structs  # noqa: N806 (this library's layout)
    c_filter_p = ctypes.c_void_p
    u32 = ctypes.c_uint32
    for name in ("propid_abi_max_rotors", "propid_abi_sizeof_config", "propid_abi_sizeof_filter",
                 "propid_abi_sizeof_estimate", "propid_abi_sizeof_counters",
                 "propid_abi_offsetof_config_gate_sigma", "propid_abi_offsetof_config_converged_rel_std",
                 "propid_abi_offsetof_estimate_health", "propid_abi_offsetof_counters_rejected",
                 "propid_abi_delay_slots"):
        getattr(lib, name).restype = u32
        getattr(lib, name).argtypes = []
    lib.propid_config_default.restype = None
    lib.propid_config_default.argtypes = [ctypes.POINTER(ConfigStruct)]
    lib.propid_config_check.restype = ctypes.c_int
    lib.propid_config_check.argtypes = [ctypes.POINTER(ConfigStruct), ctypes.POINTER(ctypes.c_char_p)]
    lib.propid_init.restype = ctypes.c_int
    lib.propid_init.argtypes = [c_filter_p, ctypes.POINTER(ConfigStruct)]
    lib.propid_reset.restype = ctypes.c_int
    lib.propid_reset.argtypes = [c_filter_p]
    lib.propid_reset_rotor.restype = ctypes.c_int
    lib.propid_reset_rotor.argtypes = [c_filter_p, ctypes.c_uint8]
    lib.propid_resync.restype = ctypes.c_int
    lib.propid_resync.argtypes = [c_filter_p, ctypes.c_uint64]
    lib.propid_push_rotor_speeds.restype = ctypes.c_int
    lib.propid_push_rotor_speeds.argtypes = [c_filter_p, ctypes.c_uint64,
                                             ctypes.POINTER(ctypes.c_float), ctypes.c_uint8]
    lib.propid_push_gyro.restype = ctypes.c_int
    lib.propid_push_gyro.argtypes = [c_filter_p, ctypes.c_uint64, ctypes.POINTER(ctypes.c_float)]
    lib.propid_push_motor_command.restype = ctypes.c_int
    lib.propid_push_motor_command.argtypes = [c_filter_p, ctypes.c_uint64,
                                              ctypes.POINTER(ctypes.c_float), ctypes.c_uint8]
    lib.propid_push_accel.restype = ctypes.c_int
    lib.propid_push_accel.argtypes = [c_filter_p, ctypes.c_uint64, ctypes.POINTER(ctypes.c_float)]
    lib.propid_get_estimate.restype = ctypes.c_int
    lib.propid_get_estimate.argtypes = [c_filter_p, ctypes.POINTER(EstimateStruct)]
    lib.propid_get_counters.restype = ctypes.c_int
    lib.propid_get_counters.argtypes = [c_filter_p, ctypes.POINTER(CountersStruct)]
    lib.propid_status_name.restype = ctypes.c_char_p
    lib.propid_status_name.argtypes = [ctypes.c_int]
    lib.propid_abi_instrument_counts.restype = None
    lib.propid_abi_instrument_counts.argtypes = [c_filter_p, ctypes.POINTER(ctypes.c_uint32)]
    lib.propid_abi_copy_state.restype = None
    lib.propid_abi_copy_state.argtypes = [c_filter_p, ctypes.POINTER(ctypes.c_float),
                                          ctypes.POINTER(ctypes.c_float)]


def _check_abi(lib: ctypes.CDLL, lib_path: Path) -> None:
    ConfigStruct, EstimateStruct = lib.propid_structs  # noqa: N806 (this library's layout)
    expected = {
        "sizeof(propid_config_t)": (lib.propid_abi_sizeof_config(), ctypes.sizeof(ConfigStruct)),
        "sizeof(propid_estimate_t)": (lib.propid_abi_sizeof_estimate(), ctypes.sizeof(EstimateStruct)),
        "sizeof(propid_counters_t)": (lib.propid_abi_sizeof_counters(), ctypes.sizeof(CountersStruct)),
        "offsetof(config.gate_sigma)": (lib.propid_abi_offsetof_config_gate_sigma(),
                                        ConfigStruct.gate_sigma.offset),
        "offsetof(config.converged_rel_std)": (lib.propid_abi_offsetof_config_converged_rel_std(),
                                               ConfigStruct.converged_rel_std.offset),
        "offsetof(estimate.health)": (lib.propid_abi_offsetof_estimate_health(),
                                      EstimateStruct.health.offset),
        "offsetof(counters.rejected)": (lib.propid_abi_offsetof_counters_rejected(),
                                        CountersStruct.rejected.offset),
    }
    if lib.propid_max_rotors == MAX_ROTORS:
        # The default build's delay buffer is mirrored by the reference filter; a
        # smaller build (the quad build: none) rejects the delays it cannot hold.
        expected["delay_slots"] = (lib.propid_abi_delay_slots(), DELAY_SLOTS)
    bad = [f"{what}: library {got}, binding {want}" for what, (got, want) in expected.items() if got != want]
    if bad:
        raise UserError(f"{lib_path} does not match propid.cfilter's struct layout ({'; '.join(bad)}); "
                        f"rebuild the library or update cfilter.py")
    for code, name in STATUS_NAME.items():
        got = lib.propid_status_name(code).decode()
        if got != name:
            raise UserError(f"{lib_path}: status {code} is {got} in C but {name} in cfilter.py")


def c_default_tuning(path: Optional[os.PathLike] = None) -> dict:
    """propid_config_default() as the library has it (for checking DEFAULT_TUNING)."""
    lib = load_library(path)
    s = lib.propid_structs[0]()
    lib.propid_config_default(ctypes.byref(s))
    return {name: getattr(s, name) for name, _ in _TUNING_FIELDS + _OPTIONAL_FIELDS + _LAST_FIELDS}


# ---------------------------------------------------------------------------
# The filter
# ---------------------------------------------------------------------------
class CFilter:
    """One propid_filter_t, owned by Python. Methods return the C status codes."""

    def __init__(self, config: FilterConfig, library: Optional[os.PathLike] = None):
        self._lib = load_library(library)
        self.config = config
        self._max_rotors = self._lib.propid_max_rotors
        self._config_struct = config.to_struct(self._max_rotors)
        bad_field = ctypes.c_char_p()
        status = self._lib.propid_config_check(ctypes.byref(self._config_struct), ctypes.byref(bad_field))
        if status != 0:
            field_name = bad_field.value.decode() if bad_field.value else "?"
            raise UserError(f"filter configuration rejected: bad {field_name}")
        size = self._lib.propid_abi_sizeof_filter()
        # ctypes buffers come from malloc: aligned for the uint64 fields inside.
        self._buffer = (ctypes.c_uint64 * ((size + 7) // 8))()
        self._handle = ctypes.cast(self._buffer, ctypes.c_void_p)
        status = self._lib.propid_init(self._handle, ctypes.byref(self._config_struct))
        if status != 0:
            raise UserError(f"propid_init failed: {self.status_name(status)}")
        self._rotor_count = config.rotor_count
        self._speeds = (ctypes.c_float * self._max_rotors)()
        self._gyro = (ctypes.c_float * 3)()
        self._accel = (ctypes.c_float * 3)()
        self._commands = (ctypes.c_float * self._max_rotors)()

    @staticmethod
    def status_name(code: int) -> str:
        return STATUS_NAME.get(int(code), f"PROPID_UNKNOWN_STATUS({int(code)})")

    def push_rotor_speeds(self, t_us: int, speeds: Sequence[float]) -> int:
        count = len(speeds)
        if count > self._max_rotors:
            # Never a valid count: C rejects it (and counts it) before reading the buffer.
            return self._lib.propid_push_rotor_speeds(self._handle, int(t_us), self._speeds, 255)
        for i in range(count):
            self._speeds[i] = float(speeds[i])
        return self._lib.propid_push_rotor_speeds(self._handle, int(t_us), self._speeds, count)

    def push_gyro(self, t_us: int, gyro: Sequence[float]) -> int:
        if len(gyro) != 3:
            raise ValueError("gyro needs 3 components [rad/s]")
        self._gyro[0], self._gyro[1], self._gyro[2] = float(gyro[0]), float(gyro[1]), float(gyro[2])
        return self._lib.propid_push_gyro(self._handle, int(t_us), self._gyro)

    def push_motor_command(self, t_us: int, commands: Sequence[float]) -> int:
        """Motor commands 0..1 (needs config.motor_command_instrument)."""
        count = len(commands)
        if count > self._max_rotors:
            return self._lib.propid_push_motor_command(self._handle, int(t_us), self._commands, 255)
        for i in range(count):
            self._commands[i] = float(commands[i])
        return self._lib.propid_push_motor_command(self._handle, int(t_us), self._commands, count)

    def push_accel(self, t_us: int, specific_force: Sequence[float]) -> int:
        """Body specific force [m/s^2] (z is fused); needs config.mass > 0."""
        if len(specific_force) != 3:
            raise ValueError("specific force needs 3 components [m/s^2]")
        for a in range(3):
            self._accel[a] = float(specific_force[a])
        return self._lib.propid_push_accel(self._handle, int(t_us), self._accel)

    def reset(self) -> int:
        return self._lib.propid_reset(self._handle)

    def reset_rotor(self, rotor: int) -> int:
        if not 0 <= int(rotor) <= 255:
            return STATUS["PROPID_ERR_ROTOR_INDEX"]
        return self._lib.propid_reset_rotor(self._handle, int(rotor))

    def resync(self, t_us: int) -> int:
        return self._lib.propid_resync(self._handle, int(t_us))

    def estimate(self) -> Estimate:
        e = self._lib.propid_structs[1]()
        status = self._lib.propid_get_estimate(self._handle, ctypes.byref(e))
        if status != 0:
            raise RuntimeError(f"propid_get_estimate: {self.status_name(status)}")
        n = self._rotor_count

        def arr(values, count):
            return np.array(values[:count], dtype=float)

        return Estimate(
            time_us=int(e.time_us),
            body_rate=arr(e.body_rate, 3), body_rate_std=arr(e.body_rate_std, 3),
            thrust_coeff=arr(e.thrust_coeff, n), thrust_coeff_std=arr(e.thrust_coeff_std, n),
            drag_coeff=arr(e.drag_coeff, n), drag_coeff_std=arr(e.drag_coeff_std, n),
            gyro_bias=arr(e.gyro_bias, 3), gyro_bias_std=arr(e.gyro_bias_std, 3),
            innovation=arr(e.innovation, 3), innovation_test_ratio=arr(e.innovation_test_ratio, 3),
            thrust_coeff_converging=int(e.thrust_coeff_converging),
            thrust_coeff_converged=int(e.thrust_coeff_converged),
            drag_coeff_converging=int(e.drag_coeff_converging),
            drag_coeff_converged=int(e.drag_coeff_converged),
            health=int(e.health), health_flags=health_names(int(e.health)),
            disturbance_torque=arr(e.disturbance_torque, 3),
            disturbance_torque_std=arr(e.disturbance_torque_std, 3),
            accel_bias=float(e.accel_bias), accel_bias_std=float(e.accel_bias_std),
            accel_innovation=float(e.accel_innovation),
            accel_innovation_test_ratio=float(e.accel_innovation_test_ratio),
            torque_scale=float(e.torque_scale), torque_scale_std=float(e.torque_scale_std),
            rotor_delay_us=int(e.rotor_delay_us), model_terms=int(e.model_terms),
        )

    def counters(self) -> dict:
        c = CountersStruct()
        self._lib.propid_get_counters(self._handle, ctypes.byref(c))
        rejected = {STATUS_NAME[-i]: int(c.rejected[i]) for i in range(1, REJECT_SLOTS) if c.rejected[i]}
        counts = (ctypes.c_uint32 * 3)()
        self._lib.propid_abi_instrument_counts(self._handle, counts)
        return {
            "gyro_accepted": int(c.gyro_accepted),
            "rotor_accepted": int(c.rotor_accepted),
            "axis_gated": [int(v) for v in c.axis_gated],
            "gate_reopened": int(c.gate_reopened),
            "cov_repairs": int(c.cov_repairs),
            "state_clamps": int(c.state_clamps),
            "resyncs": int(c.resyncs),
            "rejected": rejected,
            "accel_accepted": int(c.accel_accepted),
            "accel_gated": int(c.accel_gated),
            "accel_reanchored": int(c.accel_reanchored),
            "delay_overflows": int(c.delay_overflows),
            "model_mismatch": int(c.model_mismatch),
            "gyro_stuck": int(c.gyro_stuck),
            "command_accepted": int(counts[0]),
            "instrument_inputs": int(counts[1]),
            "instrument_guarded": int(counts[2]),
        }

    def scaled_state(self) -> tuple[np.ndarray, np.ndarray]:
        """(state, covariance) in the filter's scaled units, sized to the state count."""
        capacity = self._lib.propid_max_states
        state = (ctypes.c_float * capacity)()
        cov = (ctypes.c_float * (capacity * capacity))()
        self._lib.propid_abi_copy_state(self._handle, state, cov)
        n = self.config.state_count
        full = np.array(cov, dtype=float).reshape(capacity, capacity)
        return np.array(state[:n], dtype=float), full[:n, :n].copy()
