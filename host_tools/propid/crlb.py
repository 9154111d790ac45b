"""Cramér-Rao lower bound of kf, km and the gyro biases along a flown trajectory.

The bound is the posterior (Bayesian) Cramér-Rao bound of the filter's own
discrete model (docs/math.md sections 1-2) with the filter's own prior, process
noise and gyro noise, evaluated along the TRUE trajectory of a SITL flight
(true body rates, the rotor speeds the filter was given):

    x_{k+1} = phi(x_k, u) + w_k,   w_k ~ N(0, diag(q_rate^2 dt I3, 0, 0))
    y_k     = omega_k + b_g + v_k, v_k ~ N(0, sigma_g^2 I3)

For additive Gaussian noise the bound's recursion (Tichavsky, Muravchik &
Nehorai 1998) is the Riccati recursion of the Kalman filter with the Jacobians
taken at the true states, which is what this module runs (float64, covariance
form, because the coefficients have no process noise). The bound is what ANY
estimator with that prior could reach on that flight: the filter's convergence
time next to the bound's tells how much of it is the filter and how much the
trajectory (its excitation).

The "bound time" of a group uses the one convergence definition of
docs/results.md with the bound's standard deviation in place of the error:
the first time after which the bound's std of every state of the group stays
within 0.1 x its prior std (``t_bound_*``); ``t_bound3_*`` asks 3 bound stds
within the band (an efficient estimator then stays inside with ~99.7 %
probability per state, closer to what the filter's error criterion asks).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from propid.errors import UserError
from propid.flightlog import Vehicle
from propid.table1 import CONVERGENCE_FRACTION, convergence_time, rotor_count


@dataclass(frozen=True)
class BoundConfig:
    gyro_noise_density: float  # [rad/s/sqrt(Hz)]
    rate_process_noise: float  # q_rate [rad/s^2/sqrt(Hz)]
    rate_std0: float  # prior std of the body rates [rad/s]
    coeff_rel_std0: float  # prior std of kf_rel and km_rel
    bias_std0: float  # prior std of each gyro bias [rad/s]
    coeff_walk: float = 0.0  # random walk of kf_rel, km_rel [1/sqrt(s)]
    bias_walk: float = 0.0  # random walk of the biases [rad/s/sqrt(s)]


@dataclass
class Bound:
    t: np.ndarray  # gyro sample times [s]
    kf_std: np.ndarray  # (samples, N) relative to nominal
    km_std: np.ndarray
    bias_std: np.ndarray  # (samples, 3) [rad/s]

    def bound_times(self, coeff_band: float, bias_band: float) -> dict:
        coeff = np.hstack([self.kf_std, self.km_std])
        out = {}
        for factor, suffix in ((1.0, ""), (3.0, "3")):
            out[f"t_bound{suffix}_coeff_s"] = convergence_time(
                self.t, np.any(factor * coeff > coeff_band, axis=1))
            out[f"t_bound{suffix}_bias_s"] = convergence_time(
                self.t, np.any(factor * self.bias_std > bias_band, axis=1))
        out["bound_final_coeff_std_max"] = float(np.max(coeff[-1]))
        out["bound_final_bias_std_max"] = float(np.max(self.bias_std[-1]))
        return out


def _torque_directions(vehicle: Vehicle) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if vehicle.inertia is None or vehicle.kf_nominal is None or vehicle.km_nominal is None:
        raise UserError("the Cramér-Rao bound needs the vehicle's inertia and nominal coefficients")
    inertia = np.asarray(vehicle.inertia, dtype=float)
    inertia_inv = np.linalg.inv(inertia)
    z_axis = np.array([0.0, 0.0, 1.0])
    thrust = np.array([inertia_inv @ np.cross(r, z_axis) * kf
                       for r, kf in zip(vehicle.positions, vehicle.kf_nominal)]).T  # 3 x N
    drag = np.array([inertia_inv @ z_axis * s * km
                     for s, km in zip(vehicle.yaw_signs, vehicle.km_nominal)]).T
    return inertia, inertia_inv, np.hstack([thrust, drag])


def _gyroscopic_jacobians(inertia: np.ndarray, inertia_inv: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """d/domega of -J^-1 (omega x J omega) at each row of omega (K x 3) -> K x 3 x 3."""
    def skew(v):
        out = np.zeros(v.shape[:-1] + (3, 3))
        out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
        out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
        out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
        return out
    return -inertia_inv @ (skew(omega) @ inertia - skew(omega @ inertia.T))


@dataclass
class FlightSteps:
    """The filter's linearised step along a flight's true trajectory."""
    t: np.ndarray  # gyro sample times [s]
    dts: np.ndarray  # t[k+1] - t[k]
    steps: np.ndarray  # (samples - 1, 3, n): rate rows G_k of F_k = I + G_k
    count: int  # rotors


def flight_steps(columns: dict[str, np.ndarray], vehicle: Vehicle) -> FlightSteps:
    """F_k = I + G_k of the filter's model at the truth for every gyro step of a SITL log
    (rows at the gyro samples; true_w*, omega_i columns): gyroscopic block at the
    midpoint, trapezoid input."""
    count = rotor_count(columns)
    if count != vehicle.rotor_count:
        raise UserError(f"log has {count} rotors, vehicle {vehicle.rotor_count}")
    needed = ["t", "gyro_x", "true_wx", "true_wy", "true_wz"]
    missing = [name for name in needed if name not in columns]
    if missing:
        raise UserError(f"log lacks column(s) {', '.join(missing)} for the Cramér-Rao bound")
    rows = np.flatnonzero(np.isfinite(columns["gyro_x"]))
    if rows.size < 2:
        raise UserError("log has fewer than two gyro samples")
    t = columns["t"][rows]
    dts = np.diff(t)
    if not np.all(dts > 0):
        raise UserError("log time does not increase")
    omega = np.vstack([columns[f"true_w{a}"][rows] for a in "xyz"]).T
    speed_sq = np.vstack([columns[f"omega_{i}"][rows] for i in range(1, count + 1)]).T ** 2
    inertia, inertia_inv, torque = _torque_directions(vehicle)
    n = 6 + 2 * count
    coeff = slice(3, 3 + 2 * count)
    ubar = 0.5 * (speed_sq[1:] + speed_sq[:-1])
    steps = np.zeros((t.size - 1, 3, n))
    steps[:, :, 0:3] = dts[:, None, None] * _gyroscopic_jacobians(
        inertia, inertia_inv, 0.5 * (omega[1:] + omega[:-1]))
    steps[:, :, coeff] = dts[:, None, None] * torque[None, :, :] * np.hstack([ubar, ubar])[:, None, :]
    return FlightSteps(t=t, dts=dts, steps=steps, count=count)


def prior_covariance(config: BoundConfig, count: int) -> np.ndarray:
    return np.diag(np.concatenate([np.full(3, config.rate_std0 ** 2),
                                   np.full(2 * count, config.coeff_rel_std0 ** 2),
                                   np.full(3, config.bias_std0 ** 2)]))


def bound_along_log(columns: dict[str, np.ndarray], vehicle: Vehicle, config: BoundConfig) -> Bound:
    """The bound along one SITL log (rows at the gyro samples; true_w*, omega_i columns)."""
    flight = flight_steps(columns, vehicle)
    t, dts, steps, count = flight.t, flight.dts, flight.steps, flight.count
    n = 6 + 2 * count
    walk = np.concatenate([np.zeros(3), np.full(2 * count, config.coeff_walk ** 2),
                           np.full(3, config.bias_walk ** 2)])
    walk_on = bool(np.any(walk > 0))

    P = prior_covariance(config, count)
    samples = t.size
    out = np.empty((samples, n))
    eye3 = np.eye(3)
    for k in range(samples):
        dt = dts[k - 1] if k > 0 else dts[0]
        if k > 0:
            G = steps[k - 1]
            P[0:3, :] += G @ P                               # rate rows of F P
            P[:, 0:3] += P @ G.T                             # (F P) F^T
            P[0:3, 3:] = P[3:, 0:3].T
            P[0:3, 0:3] = 0.5 * (P[0:3, 0:3] + P[0:3, 0:3].T) + eye3 * config.rate_process_noise ** 2 * dt
            if walk_on:
                P[np.diag_indices(n)] += walk * dt
        noise_var = config.gyro_noise_density ** 2 / dt
        for axis in range(3):  # independent axes: sequential scalar updates = batch
            h = P[:, axis] + P[:, n - 3 + axis]
            P -= np.outer(h, h / (h[axis] + h[n - 3 + axis] + noise_var))
        P = 0.5 * (P + P.T)
        out[k] = P.diagonal()
    std = np.sqrt(np.maximum(out, 0.0))
    return Bound(t=t, kf_std=std[:, 3:3 + count], km_std=std[:, 3 + count:3 + 2 * count],
                 bias_std=std[:, n - 3:])


def bound_times_for_log(columns: dict[str, np.ndarray], vehicle: Vehicle, config: BoundConfig) -> dict:
    bound = bound_along_log(columns, vehicle, config)
    return bound.bound_times(CONVERGENCE_FRACTION * config.coeff_rel_std0,
                             CONVERGENCE_FRACTION * config.bias_std0)
