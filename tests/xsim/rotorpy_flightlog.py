#!/usr/bin/env python3
"""Fly one RotorPy flight and write it as a propid flight log v1 (cross-simulator check).

    rotorpy_flightlog.py --out DIR/NAME [--vehicle crazyflie|hummingbird] [--aero on|off]
                         [--trajectory lissajous|circle] [--duration S] [--log-rate HZ]
                         [--esc-rate HZ] [--seed N]

Writes NAME.csv (flight log v1), NAME.vehicle.json (what a user of RotorPy's vehicle would
write: its mass, inertia, geometry and its single nominal k_eta / k_m) and NAME.truth.json
(the answer key: true per-rotor coefficients, the aerodynamic parameters, the gyro bias;
propid's tools never read it).

RotorPy 3.0.0 does the physics (its Multirotor: rigid body, first-order motors, rotor drag,
induced inflow, translational lift and frame drag when --aero on), the control (its SE3
controller, which knows only the nominal coefficients) and the IMU (its Imu: white noise
and a constant bias). RotorPy gives every rotor the same k_eta / k_m; PerRotorMultirotor
adds each rotor's own offset to RotorPy's wrench. Frames: RotorPy's body frame is FLU with
z up and its world frame z up, as the flight log's; its rotor_directions are the sign of
each rotor's drag torque on the body, the flight log's yaw_sign; its quaternions are
[x, y, z, w], the log's (qw, qx, qy, qz). Runs in the bench-only virtual environment
(`make xsim`, tests/xsim/xsim.py); a benchmark input, not a test.
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys

import numpy as np

# The log and the vehicle file are written by propid's own writers (one writer per format). This
# script runs in the bench venv, which has RotorPy but not propid installed: the package is imported
# from the repository (its flight-log module needs numpy only).
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / "host_tools"))
from propid.flightlog import FlightLog, parse_vehicle, write_flightlog, write_vehicle  # noqa: E402

SIM_RATE_HZ = 500.0          # RotorPy step (control and physics, RK45 inside each step)
# Each rotor's thrust and drag coefficient relative to RotorPy's single value: fixed offsets
# within +-8 % (a spread of propellers), rotated by the seed so flights differ.
KF_OFFSETS = (0.06, -0.04, 0.02, -0.07)
KM_OFFSETS = (-0.05, 0.07, -0.03, 0.04)
GYRO_BIAS_STD = 0.02         # rad/s, RotorPy Imu's initial_bias drawn per axis
ROTOR_RADIUS_M = {"crazyflie": None, "hummingbird": 0.10}   # as RotorPy's parameter files give it


def vehicle_params(name: str) -> dict:
    if name == "crazyflie":
        from rotorpy.vehicles.crazyflie_params import quad_params
    else:
        from rotorpy.vehicles.hummingbird_params import quad_params
    return dict(quad_params)


def per_rotor_class():
    from rotorpy.vehicles.multirotor import Multirotor

    class PerRotorMultirotor(Multirotor):
        """RotorPy's Multirotor with a thrust and a drag coefficient per rotor.

        RotorPy's wrench (thrust k_eta Omega^2, yaw k_m Omega^2 and, with aero, its drag
        terms) plus, per rotor, the difference (kf_i - k_eta) Omega_i^2 along body z at the
        hub and rotor_dir_i (km_i - k_m) Omega_i^2 about z.
        """

        def __init__(self, params, thrust_coeff, drag_coeff, **kwargs):
            super().__init__(params, **kwargs)
            self.thrust_coeff_delta = np.asarray(thrust_coeff, float) - self.k_eta
            self.drag_coeff_delta = np.asarray(drag_coeff, float) - self.k_m

        def compute_body_wrench(self, body_rates, rotor_speeds, body_airspeed_vector):
            force, moment = super().compute_body_wrench(body_rates, rotor_speeds, body_airspeed_vector)
            speed_sq = np.asarray(rotor_speeds, float) ** 2
            extra_thrust = self.thrust_coeff_delta * speed_sq
            force = force + np.array([0.0, 0.0, extra_thrust.sum()])
            # r_i x (T_i z) = (y_i T_i, -x_i T_i, 0)
            moment = moment + np.array([
                float(self.rotor_geometry[:, 1] @ extra_thrust),
                float(-self.rotor_geometry[:, 0] @ extra_thrust),
                float(self.rotor_dir @ (self.drag_coeff_delta * speed_sq))])
            return force, moment

    return PerRotorMultirotor


class CompoundLissajous:
    """The paper's trajectory (its eq. 9, propid_sitl's default shape): a large slow Lissajous
    plus a small fast one, yaw A_psi sin(2 pi n_psi t / T). Flat outputs to snap, RotorPy's
    trajectory interface (update(t) -> dict)."""

    # (amplitude m, cycles per period) per axis, slow and fast parts; yaw amplitude, cycles.
    SLOW = ((0.6, 1.0), (0.5, 2.0), (0.02, 1.0))
    FAST = ((0.08, 10.0), (0.08, 9.0), (0.0, 8.0))
    YAW = (1.5, 1.5)

    def __init__(self, period_s: float = 10.0, height_m: float = 1.0):
        self.period = period_s
        self.height = height_m

    def _sines(self, t: float, amplitude: float, cycles: float) -> list[float]:
        # derivatives 0..4 of amplitude sin(w t)
        w = 2.0 * math.pi * cycles / self.period
        return [amplitude * w ** k * math.sin(w * t + k * math.pi / 2.0) for k in range(5)]

    def update(self, t: float) -> dict:
        derivs = np.zeros((5, 3))
        for axis in range(3):
            for amplitude, cycles in (self.SLOW[axis], self.FAST[axis]):
                derivs[:, axis] += self._sines(t, amplitude, cycles)
        derivs[0, 2] += self.height
        yaw = self._sines(t, *self.YAW)
        return {"x": derivs[0], "x_dot": derivs[1], "x_ddot": derivs[2], "x_dddot": derivs[3],
                "x_ddddot": derivs[4], "yaw": yaw[0], "yaw_dot": yaw[1], "yaw_ddot": yaw[2]}


def trajectory(name: str, vehicle: str):
    if name == "lissajous":
        return CompoundLissajous()
    from rotorpy.trajectories.circular_traj import ThreeDCircularTraj
    # RotorPy's circle with its sinusoidal yaw (yaw_bool), 1 m radius, 5 s per turn.
    return ThreeDCircularTraj(center=np.array([0.0, 0.0, 1.0]), radius=np.array([1.0, 1.0, 0.0]),
                              freq=np.array([0.2, 0.2, 0.0]), yaw_bool=True)


def fly(args) -> tuple[list[dict], dict, dict]:
    from rotorpy.controllers.quadrotor_control import SE3Control
    from rotorpy.sensors.imu import Imu

    rng = np.random.default_rng(args.seed)
    params = vehicle_params(args.vehicle)
    shift = args.seed % 4
    thrust_coeff = params["k_eta"] * (1.0 + np.roll(KF_OFFSETS, shift))
    drag_coeff = params["k_m"] * (1.0 + np.roll(KM_OFFSETS, shift))
    gyro_bias = rng.normal(0.0, GYRO_BIAS_STD, 3)
    np.random.seed(args.seed)  # RotorPy's Imu draws from numpy's global generator

    traj = trajectory(args.trajectory, args.vehicle)
    start = traj.update(0.0)
    hover = math.sqrt(params["mass"] * 9.81 / (4 * params["k_eta"]))
    initial = {"x": np.array(start["x"], float), "v": np.array(start["x_dot"], float),
               "q": np.array([0.0, 0.0, math.sin(start["yaw"] / 2), math.cos(start["yaw"] / 2)]),
               "w": np.array([0.0, 0.0, start["yaw_dot"]]), "wind": np.zeros(3), "rotor_speeds": np.full(4, hover)}
    vehicle = per_rotor_class()(params, thrust_coeff, drag_coeff, initial_state=initial,
                                aero=args.aero == "on")
    controller = SE3Control(params)
    # RotorPy's Imu with its default noise densities, sampled at the log rate, and a bias.
    imu = Imu(gyroscope_params={"initial_bias": gyro_bias.copy(),
                                "noise_density": (0.01 ** 2) * np.ones(3),
                                "random_walk": np.zeros(3)},
              sampling_rate=int(args.log_rate))

    dt = 1.0 / SIM_RATE_HZ
    steps = int(round(args.duration * SIM_RATE_HZ))
    log_every = int(round(SIM_RATE_HZ / args.log_rate))
    esc_every = int(round(SIM_RATE_HZ / args.esc_rate))
    state = {k: np.array(v, float) for k, v in initial.items()}
    rows = []
    held_speeds = state["rotor_speeds"].copy()
    for k in range(steps + 1):
        t = k * dt
        control = controller.update(t, state, traj.update(t))
        if k % esc_every == 0:
            held_speeds = state["rotor_speeds"].copy()   # the ESC's report, held until the next
        if k % log_every == 0:
            meas = imu.measurement(state, vehicle.statedot(state, control, dt), with_noise=True)
            qx, qy, qz, qw = state["q"]
            cmd = np.clip(control["cmd_motor_speeds"], params["rotor_speed_min"],
                          params["rotor_speed_max"]) / params["rotor_speed_max"]
            row = {"t": t, "gyro_x": meas["gyro"][0], "gyro_y": meas["gyro"][1], "gyro_z": meas["gyro"][2]}
            row.update({f"omega_{i + 1}": held_speeds[i] for i in range(4)})
            row.update({"acc_x": meas["accel"][0], "acc_y": meas["accel"][1], "acc_z": meas["accel"][2],
                        "qw": qw, "qx": qx, "qy": qy, "qz": qz,
                        "vx": state["v"][0], "vy": state["v"][1], "vz": state["v"][2],
                        "px": state["x"][0], "py": state["x"][1], "pz": state["x"][2]})
            row.update({f"cmd_{i + 1}": cmd[i] for i in range(4)})
            rows.append(row)
        if k < steps:
            state = vehicle.step(state, control, dt)
            if not np.all(np.isfinite(state["x"])) or np.linalg.norm(state["w"]) > 100:
                raise SystemExit(f"rotorpy_flightlog: the flight diverged at t = {t:.3f} s")

    positions = vehicle.rotor_geometry
    vehicle_file = {
        "name": f"rotorpy-{args.vehicle}",
        "mass": params["mass"],
        "inertia": [params["Ixx"], params["Iyy"], params["Izz"]],
        "rotors": [{"position": [float(c) for c in positions[i]],
                    "yaw_sign": int(params["rotor_directions"][i])} for i in range(4)],
        "kf_nominal": params["k_eta"],
        "km_nominal": params["k_m"],
        "rotor_radius": ROTOR_RADIUS_M[args.vehicle],
        "rotor_inertia": None,
        "notes": "RotorPy 3.0.0 parameter file values (mass, inertia, rotor_pos, "
                 "rotor_directions as yaw_sign, k_eta, k_m); written by tests/xsim/rotorpy_flightlog.py",
    }
    speeds = np.array([[r[f"omega_{i + 1}"] for i in range(4)] for r in rows])
    median_speed = float(np.median(speeds))
    aero = args.aero == "on"
    truth = {
        "simulator": "rotorpy", "vehicle": args.vehicle, "aero": aero,
        "trajectory": args.trajectory, "duration_s": args.duration, "seed": args.seed,
        "log_rate_hz": args.log_rate, "esc_rate_hz": args.esc_rate, "sim_rate_hz": SIM_RATE_HZ,
        "thrust_coeff": thrust_coeff.tolist(), "drag_coeff": drag_coeff.tolist(),
        "gyro_bias": gyro_bias.tolist(),
        "rotor_drag": {"k_d": params.get("k_d", 0.0) if aero else 0.0,
                       "k_z": params.get("k_z", 0.0) if aero else 0.0,
                       "k_flap": params.get("k_flap", 0.0) if aero else 0.0},
        "translational_lift_k_h": params.get("k_h", 0.0) if aero else 0.0,
        "frame_drag": [params.get(k, 0.0) if aero else 0.0 for k in ("c_Dx", "c_Dy", "c_Dz")],
        # The rate part of RotorPy's rotor drag is a body-rate damping (docs/xsim.md):
        # D_x = k_z sum Omega_i y_i^2, D_y = k_z sum Omega_i x_i^2, D_z = k_d sum Omega_i r_i^2,
        # at the median logged rotor speed.
        "aero_damping_at_median_speed": [
            (params.get("k_z", 0.0) * 4 * median_speed * float(np.mean(positions[:, 1] ** 2))) if aero else 0.0,
            (params.get("k_z", 0.0) * 4 * median_speed * float(np.mean(positions[:, 0] ** 2))) if aero else 0.0,
            (params.get("k_d", 0.0) * 4 * median_speed *
             float(np.mean(positions[:, 0] ** 2 + positions[:, 1] ** 2))) if aero else 0.0],
        "median_rotor_speed": median_speed,
    }
    return rows, vehicle_file, truth


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="output path without extension (DIR/NAME)")
    parser.add_argument("--vehicle", choices=("crazyflie", "hummingbird"), default="crazyflie")
    parser.add_argument("--aero", choices=("on", "off"), default="off",
                        help="RotorPy's aerodynamic terms (rotor drag, inflow, lift, frame drag)")
    parser.add_argument("--trajectory", choices=("lissajous", "circle"), default="lissajous",
                        help="lissajous: the paper's compound Lissajous with yaw (ours); "
                             "circle: RotorPy's circle with its sinusoidal yaw")
    parser.add_argument("--duration", type=float, default=20.0, help="seconds (20)")
    parser.add_argument("--log-rate", type=float, default=500.0,
                        help="rows per second, gyro sampled on each (500; divides 500)")
    parser.add_argument("--esc-rate", type=float, default=None,
                        help="rotor-speed reports per second, held between reports (default: the log rate)")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    if args.esc_rate is None:
        args.esc_rate = args.log_rate
    for name in ("log_rate", "esc_rate"):
        ratio = SIM_RATE_HZ / getattr(args, name)
        if ratio < 1 or abs(ratio - round(ratio)) > 1e-9:
            parser.error(f"--{name.replace('_', '-')} must divide {SIM_RATE_HZ:g} Hz")

    rows, vehicle_file, truth = fly(args)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    columns = {name: np.array([row[name] for row in rows], dtype=float) for name in rows[0]}
    log = FlightLog(t=columns.pop("t"),
                    gyro=np.column_stack([columns.pop(f"gyro_{axis}") for axis in "xyz"]),
                    rotor_speed=np.column_stack([columns.pop(f"omega_{i + 1}") for i in range(4)]),
                    extra=columns)
    write_flightlog(out.with_suffix(".csv"), log)
    # parse_vehicle checks the file as every propid tool will read it before it is written
    write_vehicle(out.with_suffix(".vehicle.json"), parse_vehicle(vehicle_file, where="RotorPy vehicle"))
    out.with_suffix(".truth.json").write_text(json.dumps(truth, indent=2) + "\n")

if __name__ == "__main__":
    main()
