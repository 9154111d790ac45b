"""The library of candidate effects: each one a set of physics regressors with
physical parameters (no black box).

Every effect adds columns to the axes it acts on. A column is the torque [N m]
(roll, pitch, yaw) or force [N] (thrust, along body z) the effect produces per unit
of one physical parameter, computed from the measured signals and the base model's
per-rotor coefficients (T_i = kf_i Omega_i^2 thrust, Q_i = km_i Omega_i^2 drag torque).
Frames: body FLU; r_i rotor hub position; s_i yaw_sign (the sign of rotor i's drag
torque on the body; the rotor spins about -s_i z).

`esc_delay` is not a column set: it is a time shift of the rotor stream, searched
before the others (alignment.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from propid.gap.prep import Flight

AXES = ("roll", "pitch", "yaw", "thrust")


@dataclass
class Context:
    """What the regressors need besides the flight: geometry and base coefficients."""

    positions: np.ndarray  # (N,3)
    yaw_signs: np.ndarray  # (N,)
    kf: np.ndarray  # (N,) base per-rotor thrust coefficients
    km: np.ndarray  # (N,)
    mass: float | None
    inertia: np.ndarray
    rotor_radius: float | None
    speed_ref: float  # median flying rotor speed over all flights [rad/s]
    # the longest log sample period over the flights [s]: a lag up to one sample is the
    # logging convention, not an effect
    sample_period_s: float = 0.0
    # False when the vehicle file has no inertia (torques are then angular accelerations and
    # the fitted torque coefficients kf/J-like ratios: bounds in absolute units do not apply)
    inertia_known: bool = True


@dataclass
class Effect:
    id: str
    params: tuple[str, ...]
    units: tuple[str, ...]
    needs: tuple[str, ...]  # inputs it needs (prep.columns_present keys)
    axes: tuple[str, ...]
    build: Callable[[Flight, Context], dict[str, np.ndarray]]  # axis -> (n, len(params)) raw columns
    physical: Callable[[np.ndarray, Context], dict] | None = None  # fitted coefficients -> physical params
    description: str = ""
    # indices of the parameters whose sign physics fixes (>= 0: an inertia, a damping, a drag
    # coefficient, a lift or ground gain, a time constant); selection.py rejects a fit that
    # needs one of them clearly negative
    nonnegative: tuple[int, ...] = ()
    # physical plausibility range of each fitted coefficient (raw column units), from the
    # vehicle's geometry (docs/gap.md "Plausibility ranges"); None where a bound is unknown
    bounds: Callable[[Context], list[tuple[float, float]]] | None = None
    # its columns are central differences of logged signals themselves (a rotor or gyro
    # acceleration), so they already carry the measured torque's difference response
    differenced: bool = False


def _thrusts(f: Flight, c: Context) -> np.ndarray:
    return f.speed**2 * c.kf[None, :]


def _moments_of(per_rotor: np.ndarray, c: Context) -> tuple[np.ndarray, np.ndarray]:
    """Roll and pitch torque of per-rotor forces along body z."""
    return per_rotor @ c.positions[:, 1], -(per_rotor @ c.positions[:, 0])


def _rotor_inertia(f: Flight, c: Context) -> dict:
    return {"yaw": (f.speed_dot @ c.yaw_signs)[:, None]}


def _rotor_gyroscopic(f: Flight, c: Context) -> dict:
    spin = f.speed @ c.yaw_signs  # sum s_i Omega_i
    return {"roll": (f.gyro[:, 1] * spin)[:, None], "pitch": (-f.gyro[:, 0] * spin)[:, None]}


def _base_predictions(f: Flight, c: Context) -> np.ndarray:
    thrusts = _thrusts(f, c)
    roll, pitch = _moments_of(thrusts, c)
    yaw = (f.speed**2 * c.km[None, :]) @ c.yaw_signs
    return np.column_stack([roll, pitch, yaw])


def _inertia_error(f: Flight, c: Context) -> dict:
    p = _base_predictions(f, c)
    zero = np.zeros(p.shape[0])
    return {"roll": np.column_stack([p[:, 0], zero]), "pitch": np.column_stack([zero, p[:, 1]])}


def _inertia_physical(coef: np.ndarray, c: Context) -> dict:
    # J_file dw/dt = P / (1 + s)  =>  response = P + alpha P with 1 + alpha = 1/(1 + s)
    scale = [1.0 / (1.0 + a) if 1.0 + a > 0 else float("nan") for a in coef]
    return {"inertia_scale_xx": scale[0], "inertia_scale_yy": scale[1]}


def _gyro_scale(f: Flight, c: Context) -> dict:
    # A (3x3) on the base torque predictions P, without A_zz: km has no independent
    # reference, so a yaw scale is absorbed by the fitted km
    p = _base_predictions(f, c)
    zero = np.zeros((p.shape[0], 3))
    return {"roll": np.column_stack([p, zero, zero[:, :2]]), "pitch": np.column_stack([zero, p, zero[:, :2]]),
            "yaw": np.column_stack([zero, zero, p[:, :2]])}


def _gyro_scale_physical(coef: np.ndarray, c: Context) -> dict:
    # measured w = M w_true  =>  J M J^-1 P = P + A P, A the fitted 3x3 (A_zz = 0: not identifiable)
    a = np.append(np.asarray(coef), 0.0).reshape(3, 3)
    j = c.inertia
    m = np.linalg.inv(j) @ (np.eye(3) + a) @ j
    return {"matrix": m.tolist(), "scale": np.diag(m).tolist()}


def _com_offset(f: Flight, c: Context) -> dict:
    total = _thrusts(f, c).sum(axis=1)
    # (r_i - d) x T_i z summed: roll gets -d_y T, pitch +d_x T
    zero = np.zeros_like(total)
    return {"roll": np.column_stack([zero, -total]), "pitch": np.column_stack([total, zero])}


def _aero_damping(f: Flight, c: Context) -> dict:
    # inflow damping grows with rotor speed: -D w (sum Omega / sum Omega at the reference speed),
    # D the damping at the reference (hover) speed
    n = f.gyro.shape[0]
    speed_factor = f.speed.sum(axis=1) / (c.speed_ref * f.speed.shape[1])
    out = {}
    for k, axis in enumerate(("roll", "pitch", "yaw")):
        col = np.zeros((n, 3))
        col[:, k] = -f.gyro[:, k] * speed_factor
        out[axis] = col
    return out


def _rotor_drag(f: Flight, c: Context) -> dict:
    v = f.body_velocity
    omega = f.speed  # (n,N)
    pos = c.positions
    # params: k_d (in-plane drag per rotor, F = -k_d Omega v_xy), k_z (axial, F = -k_z Omega v_z),
    # k_flap (flapping moment M = -k_flap Omega (z x v))
    n = v.shape[0]
    torque_d = np.zeros((n, 3))
    torque_z = np.zeros((n, 3))
    for i in range(pos.shape[0]):
        force_d = -omega[:, [i]] * np.column_stack([v[:, 0], v[:, 1], np.zeros(n)])
        force_z = -omega[:, [i]] * np.column_stack([np.zeros(n), np.zeros(n), v[:, 2]])
        torque_d += np.cross(pos[i][None, :], force_d)
        torque_z += np.cross(pos[i][None, :], force_z)
    total_speed = omega.sum(axis=1)
    flap = -total_speed[:, None] * np.column_stack([-v[:, 1], v[:, 0], np.zeros(n)])
    out = {axis: np.column_stack([torque_d[:, k], torque_z[:, k], flap[:, k]])
           for k, axis in enumerate(("roll", "pitch", "yaw"))}
    out["thrust"] = np.column_stack([np.zeros(n), -total_speed * v[:, 2], np.zeros(n)])
    return out


def _translational_lift(f: Flight, c: Context) -> dict:
    v = f.body_velocity
    return {"thrust": (len(c.kf) * (v[:, 0] ** 2 + v[:, 1] ** 2))[:, None]}


def ground_gain(height: np.ndarray, radius: float) -> np.ndarray:
    """Cheeseman-Bennett gain minus 1 at hub height h (clamped at R/2, where it is 1/3)."""
    h = np.maximum(height, 0.5 * radius)
    return 1.0 / (1.0 - (radius / (4.0 * h)) ** 2) - 1.0


def hub_heights(f: Flight, c: Context) -> np.ndarray:
    """(n, N) height of each rotor hub above the ground: pz plus the hub's world-z offset from the
    CoM, (R(q) r_i)_z; pz for every rotor when the log has no attitude."""
    if f.quat is None:
        return np.repeat(f.height[:, None], c.positions.shape[0], axis=1)
    w, x, y, z = np.asarray(f.quat, dtype=float).T
    norm = np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = (q / np.where(norm > 0, norm, 1.0) for q in (w, x, y, z))
    # third row of the body -> world rotation: the world z of a body vector
    row_z = np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1)
    return f.height[:, None] + row_z @ c.positions.T


def _ground_effect(f: Flight, c: Context) -> dict:
    # per rotor at its own hub height: tilted near the ground the lower rotors gain more thrust
    # (a restoring roll/pitch torque that the CoM height alone misses)
    gain = ground_gain(hub_heights(f, c), c.rotor_radius)
    thrusts = _thrusts(f, c) * gain
    roll, pitch = _moments_of(thrusts, c)
    return {"roll": roll[:, None], "pitch": pitch[:, None], "thrust": thrusts.sum(axis=1)[:, None]}


def _thrust_nonlinearity(f: Flight, c: Context) -> dict:
    log_ratio = np.log(np.maximum(f.speed, 1e-3) / c.speed_ref)
    thrusts = _thrusts(f, c) * log_ratio
    roll, pitch = _moments_of(thrusts, c)
    yaw = (f.speed**2 * c.km[None, :] * log_ratio) @ c.yaw_signs
    return {"roll": roll[:, None], "pitch": pitch[:, None], "yaw": yaw[:, None],
            "thrust": thrusts.sum(axis=1)[:, None]}


def _gyro_lowpass(f: Flight, c: Context) -> dict:
    # logged rate = first-order low-pass of the true rate (time constant tau):
    # w_true = w_m + tau dw_m/dt, so the true torque gains tau J d2w_m/dt2
    accel = np.gradient(f.rate_dot, f.t, axis=0) @ c.inertia.T
    return {axis: accel[:, [k]] for k, axis in enumerate(("roll", "pitch", "yaw"))}


def _residual_lag(f: Flight, c: Context) -> dict:
    # a rotor stream still late by d after the alignment: the true speeds are Omega(t + d), so
    # every axis's base prediction P gains d dP/dt to first order (one d shared by all axes),
    # dP/dt = sum_i c_ai d(Omega_i^2)/dt with c_ai the base model's per-rotor coefficients
    rate = 2.0 * f.speed * f.speed_dot
    thrust_rate = rate * c.kf[None, :]
    roll, pitch = _moments_of(thrust_rate, c)
    yaw = (rate * c.km[None, :]) @ c.yaw_signs
    return {"roll": roll[:, None], "pitch": pitch[:, None], "yaw": yaw[:, None],
            "thrust": thrust_rate.sum(axis=1)[:, None]}


def _identity_physical(names):
    def physical(coef, c):
        return {n: float(v) for n, v in zip(names, coef)}
    return physical


def _com_physical(coef, c):
    return {"com_offset_x": float(coef[0]), "com_offset_y": float(coef[1])}


# --- plausibility ranges (docs/gap.md "Plausibility ranges" gives the physics of each) ---

INF = math.inf
RHO_AIR = 1.225  # kg/m^3, standard sea-level air
MAX_SENSOR_LAG_S = 0.1  # a sensor or estimator lag beyond this would be a different vehicle (100 ms)
# below this the sensor chain's own lags (gyro filtering, the IMU decimated to the log) rule:
# every log has them, so they are not an unmodelled effect (the same floor reports esc_delay)
MIN_REPORTED_LAG_S = 0.005
MAX_THRUST_EXPONENT = 0.3  # static thrust of small fixed-pitch propellers ~ Omega^(1.7..2.3)
INERTIA_SCALE = 2.0  # the file's inertia within a factor 2 of the true one
GYRO_SCALE_ERROR = 0.1  # MEMS sensitivity tolerance (a few %) plus mounting misalignment (~5 deg), doubled
MAX_GROUND_GAIN = 2.0  # multirotor ground effect up to ~2x the single-rotor image model
UNBOUNDED = (-INF, INF)


def _hover_rotor(c: Context) -> tuple[float, float] | None:
    """Thrust per rotor at the reference speed and its induced velocity (momentum theory,
    T = 2 rho A v_i^2); None when radius, inertia (absolute kf) or a positive kf is missing."""
    kf = float(np.mean(c.kf))
    if c.rotor_radius is None or not c.inertia_known or kf <= 0:
        return None
    thrust = kf * c.speed_ref**2
    return thrust, math.sqrt(thrust / (2.0 * RHO_AIR * math.pi * c.rotor_radius**2))


def _rotor_inertia_bounds(c: Context) -> list:
    # every spinning part of a rotor weighs less than the vehicle's share m/N and sits within R
    if c.mass is None or c.rotor_radius is None or not c.inertia_known:
        return [UNBOUNDED]
    return [(-INF, c.mass * c.rotor_radius**2 / len(c.kf))]


def _inertia_bounds(c: Context) -> list:
    # scale = 1/(1 + alpha) in [1/INERTIA_SCALE, INERTIA_SCALE]
    return [(1.0 / INERTIA_SCALE - 1.0, INERTIA_SCALE - 1.0)] * 2


def _gyro_scale_bounds(c: Context) -> list:
    # M = J^-1 (I + A) J: M_ii = 1 + a_ii, M_ij = a_ij J_jj / J_ii (diagonal J)
    j = np.diag(c.inertia)
    out = []
    for k in range(8):
        i, jj = divmod(k, 3)
        limit = GYRO_SCALE_ERROR if i == jj else GYRO_SCALE_ERROR * j[i] / j[jj]
        out.append((-limit, limit))
    return out


def _lowpass_bounds(c: Context) -> list:
    """gyro_lowpass is named only above max(one log sample, MIN_REPORTED_LAG_S), the floor
    esc_delay is reported above: a shorter lag is the logging convention or the sensor
    chain's own filtering, which every log has."""
    return [(max(c.sample_period_s, MIN_REPORTED_LAG_S), MAX_SENSOR_LAG_S)]


def _com_bounds(c: Context) -> list:
    # outside the rotors' extent the vehicle cannot hover with positive thrusts
    reach = np.max(np.abs(c.positions[:, :2]), axis=0)
    return [(-reach[0], reach[0]), (-reach[1], reach[1])]


def _damping_bounds(c: Context) -> list:
    # a rotor moving axially at v changes its thrust by at most T/v_i per m/s; a body rate w
    # moves rotor i at w * (its distance from the axis); margin x2
    hover = _hover_rotor(c)
    if hover is None:
        return [UNBOUNDED] * 3
    thrust, v_i = hover
    pos = c.positions
    dist2 = (pos[:, 1] ** 2, pos[:, 0] ** 2, pos[:, 0] ** 2 + pos[:, 1] ** 2)
    return [(-INF, 2.0 * thrust / v_i * float(np.sum(d))) for d in dist2]


def _rotor_drag_bounds(c: Context) -> list:
    # in-plane drag <= mu T (mu = v / Omega R): k_d <= kf / R; axial dT/dv <= T / v_i:
    # k_z <= kf Omega_ref / v_i; flapping tilt <= 2 mu with a lever <= the arm: k_flap <= 2 kf arm / R
    hover = _hover_rotor(c)
    if hover is None:
        return [UNBOUNDED] * 3
    thrust, v_i = hover
    kf = thrust / c.speed_ref**2
    arm = float(np.max(np.linalg.norm(c.positions, axis=1)))
    r = c.rotor_radius
    return [(-INF, kf / r), (-INF, kf * c.speed_ref / v_i), (-INF, 2.0 * kf * arm / r)]


def _lift_bounds(c: Context) -> list:
    # forward flight at v >= v_i removes at most the whole induced inflow, doubling thrust
    # at most: k_h v_i^2 <= T = 2 rho A v_i^2
    if c.rotor_radius is None:
        return [UNBOUNDED]
    return [(-INF, 2.0 * RHO_AIR * math.pi * c.rotor_radius**2)]


def _ground_bounds(c: Context) -> list:
    return [(-INF, MAX_GROUND_GAIN)]


def _exponent_bounds(c: Context) -> list:
    return [(-MAX_THRUST_EXPONENT, MAX_THRUST_EXPONENT)]


EFFECTS: list[Effect] = [
    Effect("rotor_inertia", ("rotor_inertia",), ("kg m^2",), (), ("yaw",), _rotor_inertia,
           _identity_physical(("rotor_inertia",)),
           "yaw reaction of spinning rotors up/down: J_r sum s_i dOmega_i/dt", nonnegative=(0,),
           bounds=_rotor_inertia_bounds, differenced=True),
    Effect("rotor_gyroscopic", ("rotor_inertia",), ("kg m^2",), (), ("roll", "pitch"), _rotor_gyroscopic,
           _identity_physical(("rotor_inertia",)),
           "gyroscopic torque of the rotors' angular momentum: J_r sum s_i Omega_i (w x z)", nonnegative=(0,),
           bounds=_rotor_inertia_bounds),
    Effect("inertia_error", ("alpha_roll", "alpha_pitch"), ("1", "1"), ("acc", "mass", "inertia"), ("roll", "pitch"),
           _inertia_error, _inertia_physical,
           "body inertia differs from the file's: roll/pitch torque scale (needs the accelerometer kf)",
           bounds=_inertia_bounds),
    Effect("gyro_scale", tuple(f"a_{i}{j}" for i in "xyz" for j in "xyz")[:8], ("1",) * 8, ("acc", "mass", "inertia"),
           ("roll", "pitch", "yaw"), _gyro_scale, _gyro_scale_physical,
           "gyro scale and axis misalignment: measured rate M w, cross-axis coupling is its signature",
           bounds=_gyro_scale_bounds),
    Effect("gyro_lowpass", ("time_constant_s",), ("s",), (), ("roll", "pitch", "yaw"), _gyro_lowpass,
           _identity_physical(("time_constant_s",)),
           "the logged rate is low-pass filtered (sensor filter, on-board estimator): first-order lag tau", nonnegative=(0,),
           bounds=_lowpass_bounds, differenced=True),
    Effect("com_offset", ("com_offset_x", "com_offset_y"), ("m", "m"), (), ("roll", "pitch"), _com_offset,
           _com_physical, "centre of mass off the described centre: torque d x (total thrust)", bounds=_com_bounds),
    Effect("aero_damping", ("damping_x", "damping_y", "damping_z"), ("N m s/rad",) * 3, (),
           ("roll", "pitch", "yaw"), _aero_damping, _identity_physical(("damping_x", "damping_y", "damping_z")),
           "aerodynamic rate damping: torque -D w, D proportional to rotor speed (D at the median speed)", nonnegative=(0, 1, 2),
           bounds=_damping_bounds),
    Effect("rotor_drag", ("k_drag", "k_drag_axial", "k_flap"), ("N/(rad/s m/s)", "N/(rad/s m/s)", "N m/(rad/s m/s)"),
           ("velocity", "attitude"), ("roll", "pitch", "yaw", "thrust"), _rotor_drag,
           _identity_physical(("k_drag", "k_drag_axial", "k_flap")),
           "velocity-dependent rotor drag and blade flapping (body velocity from attitude + velocity)",
           nonnegative=(0, 1, 2), bounds=_rotor_drag_bounds),
    Effect("translational_lift", ("k_lift",), ("N/(m/s)^2 per rotor",), ("velocity", "attitude", "acc", "mass"),
           ("thrust",), _translational_lift, _identity_physical(("k_lift",)),
           "extra thrust in horizontal flight: k_h (v_x^2 + v_y^2) per rotor", nonnegative=(0,),
           bounds=_lift_bounds),
    Effect("ground_effect", ("ground_gain",), ("1",), ("height", "rotor_radius"), ("roll", "pitch", "thrust"),
           _ground_effect, _identity_physical(("ground_gain",)),
           "thrust gain near the ground: T (1 + s (1/(1 - (R/4h)^2) - 1))", nonnegative=(0,),
           bounds=_ground_bounds),
    Effect("thrust_nonlinearity", ("exponent",), ("1",), (), ("roll", "pitch", "yaw", "thrust"),
           _thrust_nonlinearity, _identity_physical(("exponent",)),
           "thrust/drag not exactly quadratic: T = kf Omega^2 (Omega/Omega_ref)^s",
           bounds=_exponent_bounds),
]

# Not a candidate: a nuisance that one candidate is tested on top of (CONDITIONED_ON).
RESIDUAL_LAG = Effect("residual_lag", ("delay_s",), ("s",), (), AXES, _residual_lag,
                      _identity_physical(("delay_s",)),
                      "rotor stream lag left after the alignment, linearised: d dP/dt on every axis",
                      differenced=True)

# Look-alikes that one shared physical parameter tells apart: the candidate is tested (Wald,
# held-out replication, sign, plausibility) on top of the nuisance. On yaw a telemetry lag d is,
# to first order, 2 d km Omega sum s_i dOmega_i/dt, the rotor-acceleration torque of a rotor
# inertia J_r = 2 d km Omega; but a lag delays roll, pitch and thrust by the same d, which rotor
# inertia does not touch, so those axes fix d and only the yaw torque beyond it is rotor inertia.
# The same holds for every candidate whose columns a lag can stand in for on a narrow-band motion:
# aero_damping (a torque lagging by d on a rate oscillation at frequency f is, to first order,
# a rate damping d J (2 pi f)^2) and com_offset (roll/pitch torque from the total thrust: in
# closed loop the collective and the attitude torques move together, so the band-passed thrust
# can carry part of a lag's d dP/dt).
CONDITIONED_ON = {"rotor_inertia": RESIDUAL_LAG.id, "aero_damping": RESIDUAL_LAG.id, "com_offset": RESIDUAL_LAG.id}

ESC_DELAY = "esc_delay"
ALL_IDS = [ESC_DELAY] + [e.id for e in EFFECTS]
EFFECT_AXES = {e.id: e.axes for e in EFFECTS} | {ESC_DELAY: ("roll", "pitch", "yaw")}
ESC_DELAY_NEEDS: tuple[str, ...] = ()

# Look-alikes: effects whose signatures overlap; told apart by the axes/terms that differ,
# else reported as ambiguous.
LOOK_ALIKES = [
    # the torque-vs-accelerometer scale group: each is, to first order about the hover speed, a
    # roll/pitch torque gain against the accelerometer's thrust (the exponent s scales a
    # differential torque by 1 + s/2), so all three pairs are look-alikes
    ("inertia_error", "gyro_scale"),
    ("inertia_error", "thrust_nonlinearity"),
    ("gyro_scale", "thrust_nonlinearity"),
    ("esc_delay", "rotor_inertia"),
    ("esc_delay", "gyro_lowpass"),
    ("rotor_inertia", "aero_damping"),
    ("aero_damping", "gyro_lowpass"),
    ("rotor_drag", "aero_damping"),
    ("translational_lift", "rotor_drag"),
    ("ground_effect", "thrust_nonlinearity"),
    ("com_offset", "thrust_nonlinearity"),
]


def by_id(effect_id: str) -> Effect:
    for e in EFFECTS:
        if e.id == effect_id:
            return e
    raise KeyError(effect_id)
