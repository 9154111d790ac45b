#!/usr/bin/env python3
"""The rate process noise a clean flight calls for, derived from its log, and the
rule that flies each clean soak flight on its own value (docs/reliability.md,
"The rate process noise derived"; the derivation: docs/math.md §2, "What the
prediction misses on a plant without unmodelled effects").

Per gyro step and axis the angular-acceleration increment the prediction misses
is `d_a = T sum_i B_ai (ubar_i - u_true_i)` plus Heun's term
`-(T^3 / 12) d^2 g / dt^2`:

- `u_true`: the exact mean of `Omega^2` over the step for the first-order motor
  (`tau_m`) moving towards the command held over the control period. The motor
  model runs free on the logged commands from the first row's reported speed
  (it contracts with `tau_m`, so its start-up error decays): the true speeds, not
  the telemetry's quantisation, which the input-error terms carry (math.md §14);
- `ubar`: the trapezoid of the step's end values, with reports slower than the
  gyro also the lag term `-L du/dt` (L = half the report period + its phase: the
  held report's mean age; 1.25 ms with the default SITL sensors);
- Heun's term from the filter's logged rate estimates (second difference).

White equivalent: `q_a^2 = sum over 1 s windows (sum d_a)^2 / time` (the first
0.1 s left out), `q_rate = max_a q_a`. With exact speeds (`--paper`) the same
windows over the truth residual `omega_true(k+1) - step(omega_true(k))` (the
filter's step with the true coefficients) check the derivation.

The rule: each clean flight of a soak plan (tests/soak/soak.py's plan and
commands, mode filter) is flown as the soak flies it (the matched tuning) with a
log, its `q_rate` derived, and flown again with `--filter-rate-noise q_rate`,
every other term unchanged. Prints and writes (--out) the NEES in band per
sensor set for both flights and the per-flight figures.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import random
import shlex
import subprocess
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from propid.errors import UserError
from propid.outputs import check_writable, write_text

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
# The SITL presets' motors (sitl/physics/vehicle_presets.c): time constant [s] and top
# speed [rad/s] (the log's cmd_i is the command over the top speed); the vehicle file
# the SITL writes beside its log carries neither.
MOTORS = {"crazyflie": (0.072, 2500.0), "hummingbird": (0.005, 1500.0), "hexa": (0.072, 2500.0),
          "octo": (0.072, 2500.0)}
# The SITL sensors (docs/sitl.md, "Sensors"): gyro period [s] and the held report's lag L [s].
SENSORS = {"paper": (1.0 / 500.0, 0.0), "default": (1.0 / 1000.0, 0.5 / 500.0 + 0.25e-3)}
SKIP_S = 0.1
WINDOW_S = 1.0


def load_soak():
    spec = importlib.util.spec_from_file_location("soak_for_rate_noise", HERE / "soak.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def read_log(path: str) -> tuple[dict[str, int], np.ndarray]:
    with open(path) as handle:
        header = handle.readline().strip().split(",")
    return {name: i for i, name in enumerate(header)}, np.genfromtxt(path, delimiter=",", skip_header=1)


def gyroscopic(rates: np.ndarray, inertia: np.ndarray, inertia_inv: np.ndarray) -> np.ndarray:
    """g(omega) = -J^-1 (omega x J omega), row by row."""
    return -(inertia_inv @ np.cross(rates, (inertia @ rates.T).T).T).T


def torque_per_u(arm: np.ndarray, yaw: np.ndarray, inertia_inv: np.ndarray, kf: np.ndarray,
                 km: np.ndarray) -> np.ndarray:
    """B (rows x 3 x N): d(omega_dot_a)/d(u_i) at coefficients kf, km (rows x N)."""
    torque = arm[None, :, :] * kf[:, None, :]
    torque[:, 2, :] += yaw[None, :] * km
    return np.einsum("ab,kbi->kai", inertia_inv, torque)


def white_equivalent(t: np.ndarray, increments: np.ndarray, window_s: float = WINDOW_S) -> np.ndarray:
    """Per axis sqrt(sum over windows of window_s (sum of increments)^2 / time)."""
    keep = t >= SKIP_S
    t, increments = t[keep], increments[keep]
    if len(t) < 2:
        return np.zeros(3)
    window = np.floor((t - SKIP_S) / window_s).astype(int)
    sums = np.zeros((window.max() + 1, 3))
    np.add.at(sums, window, increments)
    return np.sqrt((sums ** 2).sum(axis=0) / (t[-1] - SKIP_S))


def derive(log: str, vehicle_file: str, vehicle: str, sensors: str, truth: bool = False,
           window_s: float = WINDOW_S) -> dict:
    """q_rate of one propid_sitl log (500 Hz rows); with truth (exact speeds only) also the
    truth residual's. window_s: the white equivalent's window (default 1 s)."""
    spec = json.loads(Path(vehicle_file).read_text())
    tau_m, speed_max = MOTORS[vehicle.split("-")[0]]
    t_gyro, lag = SENSORS[sensors]
    col, x = read_log(log)
    n = len(spec["rotors"])
    inertia = np.diag(spec["inertia"]) if np.ndim(spec["inertia"]) == 1 else np.reshape(spec["inertia"], (3, 3))
    inertia_inv = np.linalg.inv(inertia)
    pos = np.array([r["position"] for r in spec["rotors"]], float)
    yaw = np.array([r["yaw_sign"] for r in spec["rotors"]], float)
    arm = np.stack([pos[:, 1], -pos[:, 0], np.zeros(n)])  # r_i x z per unit thrust

    def columns(fmt: str) -> np.ndarray:
        return x[:, [col[fmt.format(i + 1)] for i in range(n)]]

    t = x[:, col["t"]]
    period = float(np.median(np.diff(t)))
    sub = max(1, int(round(period / t_gyro)))
    omega, cmd = columns("omega_{}"), columns("cmd_{}") * speed_max
    est_kf, est_km = columns("est_kf_{}"), columns("est_km_{}")
    rows = len(t) - 1
    finite = np.isfinite(omega).all(axis=1) & np.isfinite(cmd).all(axis=1) & np.isfinite(est_kf).all(axis=1)
    valid = finite[:-1] & (np.abs(np.diff(t) - period) < 1e-6)  # the final instant is not a step
    step = t_gyro / tau_m
    mean_1, mean_2, decay = (1 - math.exp(-step)) / step, (1 - math.exp(-2 * step)) / (2 * step), math.exp(-step)
    miss = np.zeros((rows, n))
    first = int(np.argmax(valid)) if valid.any() else rows
    speed = omega[first].copy() if first < rows else np.zeros(n)
    for k in range(first, rows):
        if not valid[k]:
            continue
        command = cmd[k]
        for _ in range(sub):
            delta = speed - command
            u_true = command * command + 2 * command * delta * mean_1 + delta * delta * mean_2
            end = command + delta * decay
            u_start, u_end = speed * speed, end * end
            miss[k] += t_gyro * (0.5 * (u_start + u_end) - lag * (u_end - u_start) / t_gyro - u_true)
            speed = end
    gain = torque_per_u(arm, yaw, inertia_inv, np.nan_to_num(est_kf[:-1]), np.nan_to_num(est_km[:-1]))
    increments = np.einsum("kai,ki->ka", gain, miss)
    g = gyroscopic(np.nan_to_num(x[:, [col[f"est_w{a}"] for a in "xyz"]]), inertia, inertia_inv)
    curvature = np.zeros((rows, 3))
    curvature[1:] = (g[2:] - 2 * g[1:-1] + g[:-2]) / (period * period)
    curvature[~np.isfinite(curvature)] = 0.0
    increments -= sub * t_gyro ** 3 / 12.0 * curvature
    increments[~valid] = 0.0
    q = white_equivalent(t[:-1], increments, window_s)
    out = {"q_axes": q.tolist(), "q_rate": float(q.max())}
    if truth:
        rates = x[:, [col[f"true_w{a}"] for a in "xyz"]]
        gain = torque_per_u(arm, yaw, inertia_inv, columns("true_kf_{}")[:-1], columns("true_km_{}")[:-1])
        rotor = np.einsum("kai,ki->ka", gain, 0.5 * (omega[:-1] ** 2 + omega[1:] ** 2))
        g_start = gyroscopic(rates[:-1], inertia, inertia_inv)
        predictor = rates[:-1] + period * (rotor + g_start)
        stepped = rates[:-1] + period * rotor + 0.5 * period * (g_start + gyroscopic(predictor, inertia, inertia_inv))
        residual = rates[1:] - stepped
        residual[~valid] = 0.0
        q_truth = white_equivalent(t[:-1], residual, window_s)
        out["truth_q_axes"] = q_truth.tolist()
        out["truth_q_rate"] = float(q_truth.max())
    return out


def nees_figures(summary: str, proc: subprocess.CompletedProcess) -> dict:
    if not os.path.exists(summary):
        return {"error": proc.stderr[-300:], "exit": proc.returncode}
    data = json.loads(Path(summary).read_text())
    honesty = data.get("honesty", {})
    inside, samples = int(honesty.get("nees_in_bounds", 0)), int(honesty.get("nees_samples", 0))
    below, above = int(honesty.get("nees_below_bounds", 0)), int(honesty.get("nees_above_bounds", 0))
    return {"exit": proc.returncode, "inside": inside, "below": below, "above": above, "samples": samples,
            "in_band_pct": round(100 * inside / samples, 2) if samples else None,
            "nees_per_dof": round(honesty.get("nees_mean", 0.0) / max(1, honesty.get("nees_dof", 1)), 3),
            "cov_repairs": int(data.get("cov_repairs", 0)), "cov_not_pd": int(honesty.get("cov_not_pd", 0)),
            "cov_checks": int(honesty.get("cov_checks", 0)), "false_converged": int(honesty.get("false_converged", 0)),
            "converged_claims": int(honesty.get("converged_claims", 0)),
            "nonfinite": int(honesty.get("nonfinite_estimates", 0))}


def fly_case(job: tuple) -> dict:
    soak_path, sitl, case, truth, extra = job
    soak = load_soak()
    with tempfile.TemporaryDirectory(prefix="rate-noise-") as work:
        log = os.path.join(work, "matched.csv")
        summary = os.path.join(work, "matched.json")
        proc = subprocess.run(soak.command(sitl, case, "filter", summary) + extra + ["--log", log],
                              capture_output=True, text=True)
        matched = nees_figures(summary, proc)
        if not os.path.exists(log):
            return {"case": case, "matched": matched, "error": "no log"}
        derived = derive(log, log[:-4] + ".vehicle.json", case["vehicle"], case["sensors"],
                         truth and case["sensors"] == "paper")
        summary = os.path.join(work, "derived.json")
        proc = subprocess.run(soak.command(sitl, case, "filter", summary) + extra
                              + ["--filter-rate-noise", f"{derived['q_rate']:.6g}"], capture_output=True, text=True)
        return {"case": case, "matched": matched, "derived_q": derived, "derived": nees_figures(summary, proc)}


# The previous-flight rule: a NEES flight with exact rotor speeds (the paper sensors: no
# input error, so the rate process noise covers only the prediction's discretisation
# miss) takes the q_rate derived from a previous flight of the same vehicle flying the
# same mission: the case with another seed (another draw of the coefficients, biases
# and noise), flown as the soak flies it, with a log. Flights with input errors keep the
# matched tuning's rate noise, which also covers the held input error the derivation
# leaves out.
RATE_RULES = ("none", "previous-flight")
CALIBRATION_SEED_OFFSET = 500000


def rule_applies(rule: str, case: dict) -> bool:
    return rule == "previous-flight" and case["clean"] and case["sensors"] == "paper"


def calibrate(case: dict, command_of, window_s: float = WINDOW_S) -> dict:
    """Fly the case's calibration flight (command_of(case, summary) -> propid_sitl command,
    mode filter) with a log and derive its q_rate; {"error": ...} if it did not fly."""
    previous = {**case, "seed": case["seed"] + CALIBRATION_SEED_OFFSET}
    previous.pop("rate_noise", None)
    with tempfile.TemporaryDirectory(prefix="rate-rule-") as work:
        log, summary = os.path.join(work, "previous.csv"), os.path.join(work, "previous.json")
        proc = subprocess.run(command_of(previous, summary) + ["--log", log], capture_output=True, text=True)
        if proc.returncode != 0 or not os.path.exists(log):
            return {"error": f"calibration flight exit {proc.returncode}: {proc.stderr.strip()[-200:]}"}
        derived = derive(log, log[:-4] + ".vehicle.json", case["vehicle"], case["sensors"], window_s=window_s)
        return {"q_rate": derived["q_rate"], "seed": previous["seed"]}


# A flight counts as outside the band when fewer of its NEES samples than this lie in it
# (the target's 90 %); it is underconfident when more of the others lie below than above.
FLIGHT_IN_BAND_PCT = 90.0


def pooled(results: list[dict], key: str) -> dict:
    """Per sensor set: the share of NEES samples in their 95 % band, below it (the sigma too
    large, the safe side) and above it (overconfident); the flights under FLIGHT_IN_BAND_PCT
    in band, by the side most of their other samples lie on; the totals."""
    groups: dict[str, list[int]] = {}
    totals = {"cov_repairs": 0, "cov_not_pd": 0, "cov_checks": 0, "false_converged": 0, "converged_claims": 0,
              "nonfinite": 0, "errors": 0}
    for result in results:
        figures = result.get(key)
        if figures is None or "error" in figures or figures["exit"] != 0:
            totals["errors"] += 1
            continue
        for name in totals:
            if name != "errors":
                totals[name] += figures[name]
        group = groups.setdefault(result["case"]["sensors"], [0, 0, 0, 0, 0, 0, 0])
        below, above = figures.get("below", 0), figures.get("above", 0)
        group[0] += figures["inside"]
        group[1] += figures["samples"]
        group[2] += 1
        group[3] += below
        group[4] += above
        if figures["samples"] and 100 * figures["inside"] < FLIGHT_IN_BAND_PCT * figures["samples"]:
            group[5 if below >= above else 6] += 1
    inside, samples = sum(g[0] for g in groups.values()), sum(g[1] for g in groups.values())

    def share(part: int, whole: int) -> float | None:
        return round(100 * part / whole, 2) if whole else None

    return {"in_band_pct": share(inside, samples),
            **{f"{name} sensors": {"in_band_pct": share(g[0], g[1]), "below_band_pct": share(g[3], g[1]),
                                   "above_band_pct": share(g[4], g[1]), "flights": g[2],
                                   "flights_outside_under": g[5], "flights_outside_over": g[6]}
               for name, g in sorted(groups.items())}, **totals}


def add_plan_arguments(parser: argparse.ArgumentParser) -> None:
    """The options every NEES tool here shares: the SITL binary, and the soak plan's seed and size."""
    parser.add_argument("--sitl", default=str(REPO / "build" / "host" / "sitl" / "propid_sitl"),
                        help="propid_sitl binary (default: build/host/sitl/propid_sitl)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the soak plan (default 1, make soak's)")
    parser.add_argument("--steps", type=float, default=1e7, help="the plan's filter steps, as make soak (default 1e7)")


def check_sitl_and_out(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """--sitl must be an executable; --out is checked writable now (the host tools' rule, README "Output
    files"), its directories made at the write."""
    if not os.access(args.sitl, os.X_OK):
        parser.error(f"--sitl: {args.sitl} is not an executable (build it: make host)")
    if args.out:
        try:
            check_writable(args.out, "--out")
        except UserError as exc:
            parser.error(str(exc))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_plan_arguments(parser)
    parser.add_argument("--jobs", type=int, default=2, help="flights in parallel (default 2)")
    parser.add_argument("--truth", action="store_true",
                        help="also the truth residual's white equivalent on exact-speed flights")
    parser.add_argument("--out", help="write the figures and the per-flight results here (JSON)")
    parser.add_argument("--log", help="derive q_rate of one existing propid_sitl log instead (needs --vehicle, --sensors)")
    parser.add_argument("--vehicle", help="with --log: the SITL preset flown")
    parser.add_argument("--sensors", choices=sorted(SENSORS), help="with --log: paper or default")
    parser.add_argument("--default-args", default="",
                        help="extra propid_sitl options for both flights of the default-sensor cases, one string "
                             "(e.g. \"--filter-rotor-speed-noise-hold-floor\"; default none)")
    args = parser.parse_args(argv)
    if args.log:
        if not (args.vehicle and args.sensors):
            parser.error("--log needs --vehicle and --sensors")
        if args.vehicle.split("-")[0] not in MOTORS:
            parser.error(f"--vehicle: no motor model for {args.vehicle} (SITL presets: {', '.join(sorted(MOTORS))})")
        print(json.dumps(derive(args.log, args.log[:-4] + ".vehicle.json", args.vehicle, args.sensors,
                                args.truth and args.sensors == "paper")))
        return 0
    check_sitl_and_out(parser, args)
    soak = load_soak()
    rng = random.Random(args.seed)
    cases, planned = [], 0.0
    while planned < 1.05 * args.steps:  # the plan exactly as make soak draws it
        case = soak.plan_case(rng, len(cases))
        cases.append(case)
        planned += 2.0 * soak.expected_steps(case)
    clean = [case for case in cases if case["clean"]]
    try:
        from tqdm import tqdm
    except ImportError:  # the bar is a convenience
        tqdm = None
    extra = {"default": shlex.split(args.default_args), "paper": []}
    jobs = [(str(HERE / "soak.py"), args.sitl, case, args.truth, extra[case["sensors"]]) for case in clean]
    with ProcessPoolExecutor(args.jobs) as pool:
        iterator = pool.map(fly_case, jobs)
        if tqdm:
            iterator = tqdm(iterator, total=len(jobs), unit="flight", desc=f"plan {args.seed}", file=sys.stderr)
        results = list(iterator)
    out = {"plan_seed": args.seed, "default_args": args.default_args, "matched": pooled(results, "matched"),
           "derived": pooled(results, "derived"), "flights": results}
    if args.out:
        write_text(args.out, json.dumps(out, indent=1) + "\n")
    print(json.dumps({key: out[key] for key in ("plan_seed", "default_args", "matched", "derived")}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
