"""The firmware filter (the C library through propid.cfilter) behind the few calls a replay
needs; estimates come back as plain lists of floats."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.realdata_checks import flying_mask


def _field(obj, name):
    """Read a field from a dict, a dataclass or a ctypes structure alike."""
    value = obj[name] if isinstance(obj, dict) else getattr(obj, name)
    if hasattr(value, "_length_") or isinstance(value, (list, tuple, np.ndarray)):
        return [float(v) for v in value]
    return value


class FilterSession:
    """One C filter configured from the vehicle and the replay's configuration fields."""

    def __init__(self, vehicle: Vehicle, config_fields: dict):
        from propid import cfilter  # the C library itself, not a Python re-implementation

        geometry = {"rotor_count", "positions", "yaw_signs", "thrust_coeff_nominal", "drag_coeff_nominal", "inertia"}
        # The replay may run with other nominals or a unit inertia than the vehicle file's.
        self.vehicle = replace(
            vehicle,
            inertia=np.asarray(config_fields["inertia"], dtype=float),
            kf_nominal=list(config_fields["thrust_coeff_nominal"]),
            km_nominal=list(config_fields["drag_coeff_nominal"]),
        )
        overrides = {k: v for k, v in config_fields.items() if k not in geometry}
        try:
            config = cfilter.FilterConfig.from_vehicle(self.vehicle, **overrides)
            self._filter = cfilter.CFilter(config)
        except (ValueError, TypeError) as exc:
            raise UserError(f"the filter rejected its configuration: {exc}") from None
        self.rotor_count = vehicle.rotor_count
        self.TIME_JUMP = cfilter.STATUS["PROPID_ERR_TIME_JUMP"]

    def push_rotor_speeds(self, t_us: int, speeds: np.ndarray) -> int:
        return int(self._filter.push_rotor_speeds(t_us, speeds))

    def push_gyro(self, t_us: int, gyro: np.ndarray) -> int:
        return int(self._filter.push_gyro(t_us, gyro))

    def push_motor_command(self, t_us: int, commands: np.ndarray) -> int:
        return int(self._filter.push_motor_command(t_us, commands))

    def push_accel(self, t_us: int, specific_force: np.ndarray) -> int:
        return int(self._filter.push_accel(t_us, specific_force))

    def resync(self, t_us: int) -> int:
        return int(self._filter.resync(t_us))

    def status_name(self, code: int) -> str:
        return str(self._filter.status_name(code))

    def estimate(self) -> dict:
        est = self._filter.estimate()
        names = ("body_rate", "thrust_coeff", "thrust_coeff_std", "drag_coeff", "drag_coeff_std", "gyro_bias",
                 "gyro_bias_std",
                 "thrust_coeff_converged", "drag_coeff_converged", "health", "innovation_test_ratio",
                 "disturbance_torque", "disturbance_torque_std", "accel_bias", "accel_bias_std",
                 "torque_scale", "torque_scale_std")
        return {name: _field(est, name) for name in names}

    def thrust_coeff_covariance(self) -> np.ndarray:
        """Covariance of the rotors' kf [(N/(rad/s)^2)^2] now, to first order: kf_i = kf_nominal_i kf_rel_i, and
        with the thrust-torque scale kf_rel_i = r g_i, r the last state (docs/math.md §6, §9)."""
        state, cov = self._filter.scaled_state()
        n = self.rotor_count
        jac = np.zeros((n, state.size))
        scaled = bool(self._filter.config.torque_scale)
        r = state[-1] if scaled else 1.0
        for i in range(n):
            jac[i, 3 + i] = r
            if scaled:
                jac[i, -1] = state[3 + i]
        jac *= np.asarray(self.vehicle.kf_nominal, dtype=float)[:, None]
        return jac @ cov @ jac.T

    def drag_coeff_rel_covariance(self) -> np.ndarray:
        """Covariance of the rotors' km relative to their nominal (km_rel, per rotor) now."""
        _, cov = self._filter.scaled_state()
        n = self.rotor_count
        return cov[3 + n:3 + 2 * n, 3 + n:3 + 2 * n].copy()

    def counters(self) -> dict:
        return dict(self._filter.counters())


def segment_mask(log: FlightLog, segment: str) -> np.ndarray:
    if segment == "all":
        return np.ones(len(log), dtype=bool)
    if segment == "flying":
        return flying_mask(log)
    raise UserError(f"--segment {segment!r}: choose all or flying")

