"""Linearised signatures of the candidate effects, for the least-squares baseline.

Each effect is a group of columns in the stacked (roll, pitch, yaw, thrust) model of
propid.gapbench.rigid_body, each column an array (4, n) of what the effect adds to
the model side per unit of a linear parameter. Derived from the physics of each
effect to first order (docs/gap-bench.md); no column uses anything the blind log
and the vehicle file do not hold. An effect whose inputs are missing (no
velocity, no height, no rotor radius, ...) returns None: untestable.
"""

from __future__ import annotations

import numpy as np

from propid.flightlog import Vehicle
from propid.gapbench.rigid_body import Grid, inertia_matrix
from propid.signals import world_to_body

GRAVITY = 9.81


def _stack(roll=None, pitch=None, yaw=None, thrust=None, n: int = 0) -> np.ndarray:
    out = np.zeros((4, n))
    for k, row in enumerate((roll, pitch, yaw, thrust)):
        if row is not None:
            out[k] = row
    return out


def _body_velocity(grid: Grid) -> np.ndarray | None:
    if grid.quat is None or grid.vel is None:
        return None
    return world_to_body(grid.quat, grid.vel)


def _coefficients(vehicle: Vehicle, count: int) -> tuple[np.ndarray, np.ndarray]:
    kf = np.asarray(vehicle.kf_nominal if vehicle.kf_nominal else [1.0] * count, dtype=float)
    km = np.asarray(vehicle.km_nominal if vehicle.km_nominal else [1.0] * count, dtype=float)
    return kf, km


def _nominal_of(grid: Grid, vehicle: Vehicle, per_rotor: np.ndarray) -> np.ndarray:
    """The nominal model's four rows with W_i^2 replaced by `per_rotor` (n, N)."""
    pos, signs = vehicle.positions, vehicle.yaw_signs
    kf, km = _coefficients(vehicle, pos.shape[0])
    thrust = per_rotor * kf
    return _stack(thrust @ pos[:, 1], -(thrust @ pos[:, 0]), (per_rotor * km) @ signs,
                  thrust.sum(axis=1), n=per_rotor.shape[0])


def effect_columns(effect: str, grid: Grid, vehicle: Vehicle) -> list[np.ndarray] | None:
    n = grid.t.size
    pos, signs = vehicle.positions, vehicle.yaw_signs
    speed = grid.speed
    v_b = _body_velocity(grid)
    if effect == "rotor_inertia":
        return [_stack(yaw=grid.speed_dot @ signs, n=n)]
    if effect == "rotor_gyroscopic":
        h_z = -(speed @ signs)
        return [_stack(roll=-grid.rate[:, 1] * h_z, pitch=grid.rate[:, 0] * h_z, n=n)]
    if effect == "rotor_drag":
        if v_b is None:
            return None
        total = speed.sum(axis=1)
        flapping = _stack(roll=total * v_b[:, 1], pitch=-total * v_b[:, 0], n=n)
        inflow = _stack(roll=-(speed @ pos[:, 1]) * v_b[:, 2], pitch=(speed @ pos[:, 0]) * v_b[:, 2],
                        thrust=-total * v_b[:, 2], n=n)
        in_plane = _stack(yaw=-(speed @ pos[:, 0]) * v_b[:, 1] + (speed @ pos[:, 1]) * v_b[:, 0], n=n)
        return [flapping, inflow, in_plane]
    if effect == "translational_lift":
        if v_b is None:
            return None
        return [_stack(thrust=pos.shape[0] * (v_b[:, 0] ** 2 + v_b[:, 1] ** 2), n=n)]
    if effect == "ground_effect":
        if grid.pos is None or vehicle.rotor_radius is None:
            return None
        height = np.maximum(grid.pos[:, 2], vehicle.rotor_radius / 2)
        gain = 1.0 / (1.0 - (vehicle.rotor_radius / (4.0 * height)) ** 2) - 1.0
        return [_nominal_of(grid, vehicle, grid.speed_sq * gain[:, None])]
    if effect == "com_offset":
        kf, _ = _coefficients(vehicle, pos.shape[0])
        thrust = grid.speed_sq @ kf
        return [_stack(roll=thrust, n=n), _stack(pitch=thrust, n=n)]
    if effect == "inertia_error":
        inertia = inertia_matrix(vehicle)
        torque = grid.rate_dot @ inertia.T + np.cross(grid.rate, grid.rate @ inertia.T)
        return [_stack(-torque[:, 0], -torque[:, 1], -torque[:, 2], n=n)]
    if effect == "esc_delay":
        return [_nominal_of(grid, vehicle, grid.speed_sq_dot)]
    if effect == "thrust_nonlinearity":
        reference = np.median(speed[speed > 0]) if np.any(speed > 0) else 1.0
        if vehicle.mass is not None and vehicle.kf_nominal:
            reference = np.sqrt(vehicle.mass * GRAVITY / sum(vehicle.kf_nominal))
        log_ratio = np.log(np.maximum(speed, 1e-3 * reference) / reference)
        return [_nominal_of(grid, vehicle, grid.speed_sq * log_ratio)]
    if effect == "gyro_scale":
        inertia = np.diag(inertia_matrix(vehicle))
        acc = grid.rate_dot
        columns = [_stack(roll=-inertia[0] * acc[:, 0], n=n), _stack(pitch=-inertia[1] * acc[:, 1], n=n)]
        for row in range(3):
            for col in range(3):
                if row != col:
                    rows = [None, None, None]
                    rows[row] = -inertia[row] * acc[:, col]
                    columns.append(_stack(*rows, n=n))
        return columns
    if effect == "aero_damping":
        return [_stack(roll=-grid.rate[:, 0] * (speed @ pos[:, 1] ** 2), n=n),
                _stack(pitch=-grid.rate[:, 1] * (speed @ pos[:, 0] ** 2), n=n),
                _stack(yaw=-grid.rate[:, 2] * (speed @ (pos[:, 0] ** 2 + pos[:, 1] ** 2)), n=n)]
    raise ValueError(f"unknown effect {effect!r}")
