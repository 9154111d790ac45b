#!/usr/bin/env python3
"""`make xsim`: `propid gap` and `propid replay` on flights of a simulator that is not ours.

    xsim.py --repo DIR --build DIR [--out DIR] [--result FILE] [--flights NAME,...]
            [--duration S] [--no-fly]

A cross-simulator check, not a test (docs/xsim.md): RotorPy (the paper's authors'
simulator, pinned, in the bench-only venv) flies a few short flights with its own
dynamics, motors, aerodynamics and IMU (tests/xsim/rotorpy_flightlog.py writes each as a
flight log v1 and a vehicle file, and its truth to an answer key the tools never read);
`propid gap` and `propid replay` (gyro only, with its default aiding, and gyro only with the
vehicle file `propid gap --vehicle-out` corrected, its aero damping carried, and with the
accelerometer's thrust airspeed terms fitted by `--thrust-aero-out` and removed) run on each;
every answer is scored against the expectations written before the first run
(docs/xsim.md, "Expected answers"). Prints a table and writes --result
(default BUILD/results/xsim.json). Exits non-zero only when a step cannot run.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import subprocess
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "bench"))
from bench_venv import ensure_bench_venv  # noqa: E402

# name: (vehicle, aero, trajectory, log rate Hz, ESC report rate Hz, seed)
FLIGHTS = {
    "cf-liss-off": ("crazyflie", "off", "lissajous", 500, 500, 1),
    "cf-liss-on": ("crazyflie", "on", "lissajous", 500, 500, 2),
    "cf-circle-off-100hz": ("crazyflie", "off", "circle", 100, 100, 3),
    "cf-liss-on-esc100": ("crazyflie", "on", "lissajous", 500, 100, 4),
    "hb-liss-off": ("hummingbird", "off", "lissajous", 500, 500, 5),
    "hb-liss-on": ("hummingbird", "on", "lissajous", 500, 500, 6),
    "hb-circle-on-100hz": ("hummingbird", "on", "circle", 100, 100, 7),
}
# The expectations (docs/xsim.md, fixed before the first run).
AERO_IDS = {"crazyflie": {"aero_damping", "rotor_drag"},
            "hummingbird": {"aero_damping", "rotor_drag", "translational_lift"}}
BASE_FIT_KF_TOL = 0.05
BASE_FIT_KM_TOL = 0.10
REPLAY_KF_TOL = 0.05
REPLAY_SIGMAS = 3.0
REPLAY_FLEET_TOL = 0.03
DAMPING_FACTOR = 2.0
# gap as it is by default, and with the gyro bias measured against the logged attitude
# (`--gyro-bias attitude`, evaluated: docs/gap.md "Data preparation", docs/xsim.md)
GAP_VARIANTS = (("", []), ("-gyro-bias-attitude", ["--gyro-bias", "attitude"]))


def say(text: str) -> None:
    print(f"xsim: {text}", flush=True)


def run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    result = subprocess.run(cmd, text=True, capture_output=True, **kw)
    if result.returncode != 0:
        tail = (result.stderr or result.stdout).strip().splitlines()[-3:]
        raise RuntimeError(f"{' '.join(cmd[:3])} ... failed ({result.returncode}): " + " | ".join(tail))
    return result


def ratio(value, truth):
    return None if value is None or truth in (None, 0) else value / truth


def score_gap(gap: dict, truth: dict) -> dict:
    aero = truth["aero"]
    named = [e["id"] for e in gap["effects"] if e.get("significant")]
    kf_true = sum(truth["thrust_coeff"]) / len(truth["thrust_coeff"])
    km_true = sum(truth["drag_coeff"]) / len(truth["drag_coeff"])

    def fit_ratios(fit):
        fit = fit or {}
        out = {}
        for key, true in (("kf_thrust", kf_true), ("kf_roll", kf_true), ("kf_pitch", kf_true),
                          ("km_yaw", km_true)):
            entry = fit.get(key)
            out[key] = ratio(entry["value"], true) if entry else None
        return out

    before, after = fit_ratios(gap.get("base_fit")), fit_ratios(gap.get("base_fit_after"))
    judged = before if not aero else after
    fit_ok = all(judged[k] is not None and abs(judged[k] - 1) <= BASE_FIT_KF_TOL
                 for k in ("kf_thrust", "kf_roll", "kf_pitch"))
    if not aero:
        fit_ok = fit_ok and judged["km_yaw"] is not None and abs(judged["km_yaw"] - 1) <= BASE_FIT_KM_TOL
    if aero:
        allowed = AERO_IDS[truth["vehicle"]]
        verdict_ok = gap["verdict"] in allowed and set(named) <= allowed
    else:
        allowed = set()
        verdict_ok = gap["verdict"] == "none" and not named
    out = {"verdict": gap["verdict"], "significant": named, "expected_ids": sorted(allowed) or ["none"],
           "verdict_right": verdict_ok, "base_fit_ratio": before, "base_fit_after_ratio": after,
           "base_fit_right": fit_ok, "false_ids": sorted(set(named) - allowed)}
    damping = next((e for e in gap["effects"] if e["id"] == "aero_damping"), None)
    if aero:
        derived = truth["aero_damping_at_median_speed"]
        entry = {"derived": derived, "named": "aero_damping" in named}
        if damping:
            fitted = [damping["params"].get(f"damping_{a}") for a in "xyz"]
            entry["fitted"] = fitted
            entry["ratio"] = [ratio(f, d) for f, d in zip(fitted, derived)]
            entry["within_factor_2"] = all(r is not None and 1 / DAMPING_FACTOR <= r <= DAMPING_FACTOR
                                           for r in entry["ratio"])
        out["aero_damping"] = entry
        if truth["vehicle"] == "crazyflie" and truth["trajectory"] == "lissajous":
            out["aero_damping_named_as_expected"] = entry["named"]
        drag = next((e for e in gap["effects"] if e["id"] == "rotor_drag"), None)
        if drag:
            out["rotor_drag"] = {"params": drag["params"], "significant": drag.get("significant"),
                                 "implausible": drag.get("implausible")}
    return out


def score_replay(replay: dict, truth: dict) -> dict:
    kf, kf_std = replay["kf"], replay["kf_std"]
    km, km_std = replay["km"], replay["km_std"]
    kf_true, km_true = truth["thrust_coeff"], truth["drag_coeff"]
    kf_sig = [(k - t) / s for k, t, s in zip(kf, kf_true, kf_std)]
    km_sig = [(k - t) / s for k, t, s in zip(km, km_true, km_std)]
    kf_rel = [k / t - 1 for k, t in zip(kf, kf_true)]
    fleet = (sum(kf) / len(kf)) / (sum(kf_true) / len(kf_true))
    right = (all(abs(s) <= REPLAY_SIGMAS for s in kf_sig) and all(abs(r) <= REPLAY_KF_TOL for r in kf_rel)
             and all(abs(s) <= REPLAY_SIGMAS for s in km_sig) and abs(fleet - 1) <= REPLAY_FLEET_TOL)
    return {"aiding": replay.get("aiding"), "kf_ratio": [k / t for k, t in zip(kf, kf_true)],
            "kf_error_sigmas": kf_sig, "km_ratio": [k / t for k, t in zip(km, km_true)],
            "km_error_sigmas": km_sig, "fleet_kf_ratio": fleet, "right": right,
            "gyro_bias": replay.get("gyro_bias"), "gyro_bias_true": truth["gyro_bias"]}


def thrust_aero_fit(path: pathlib.Path, truth: dict) -> dict:
    """The airspeed terms `propid replay --thrust-aero-out` fitted, beside RotorPy's: its axial
    inflow -k_z per rotor (the climb term) and its translational lift k_h."""
    fitted = json.loads(path.read_text())
    return {"thrust_climb_coeff": fitted.get("thrust_climb_coeff"),
            "rotorpy_minus_k_z": -truth["rotor_drag"]["k_z"],
            "thrust_translational_coeff": fitted.get("thrust_translational_coeff"),
            "rotorpy_k_h": truth["translational_lift_k_h"]}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", type=pathlib.Path, required=True)
    parser.add_argument("--build", type=pathlib.Path, required=True)
    parser.add_argument("--out", type=pathlib.Path, help="flight logs and outputs (default BUILD/xsim)")
    parser.add_argument("--result", type=pathlib.Path, help="JSON (default BUILD/results/xsim.json)")
    parser.add_argument("--flights", default=",".join(FLIGHTS), help="comma-separated subset of: "
                        + ", ".join(FLIGHTS))
    parser.add_argument("--duration", type=float, default=20.0, help="seconds per flight (20)")
    parser.add_argument("--no-fly", action="store_true", help="reuse the flight logs already in --out")
    args = parser.parse_args()
    repo, build = args.repo.resolve(), args.build.resolve()
    out = (args.out or build / "xsim").resolve()
    result_path = (args.result or build / "results/xsim.json").resolve()
    names = [n for n in args.flights.split(",") if n]
    unknown = [n for n in names if n not in FLIGHTS]
    if unknown:
        parser.error(f"unknown flight(s) {', '.join(unknown)}; choose from {', '.join(FLIGHTS)}")
    propid = pathlib.Path(sys.executable).parent / "propid"
    try:
        bench_python = None if args.no_fly else ensure_bench_venv(repo, build, say)
    except (subprocess.CalledProcessError, OSError) as error:
        print(f"xsim: error: the bench venv with RotorPy could not be installed: {error}", file=sys.stderr)
        return 1
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    try:
        for index, name in enumerate(names, 1):
            vehicle, aero, traj, log_rate, esc_rate, seed = FLIGHTS[name]
            stem = out / name
            t0 = time.time()
            if not args.no_fly:
                say(f"[{index}/{len(names)}] {name}: RotorPy flight ({args.duration:g} s)...")
                run([str(bench_python), str(repo / "tests/xsim/rotorpy_flightlog.py"), "--out", str(stem),
                     "--vehicle", vehicle, "--aero", aero, "--trajectory", traj,
                     "--duration", str(args.duration), "--log-rate", str(log_rate),
                     "--esc-rate", str(esc_rate), "--seed", str(seed)])
            truth = json.loads(stem.with_suffix(".truth.json").read_text())
            csv = str(stem.with_suffix(".csv"))
            say(f"[{index}/{len(names)}] {name}: propid gap, propid replay...")
            gaps = {}
            corrected = out / f"{name}.corrected.vehicle.json"
            for label, extra in GAP_VARIANTS:
                path = out / f"{name}.gap{label}.json"
                if not label:  # the default run also writes its corrected vehicle file
                    extra = ["--vehicle-out", str(corrected), "--calibration", "off"]
                run([str(propid), "gap", "--log", csv, "--json", str(path), "--no-filter", "--no-progress"] + extra)
                gaps[label or "default"] = score_gap(json.loads(path.read_text()), truth)
            replays = {}
            # the thrust's airspeed terms fitted from the accelerometer (replay --thrust-aero-out) for the
            # accelerometer-aided replay with --thrust-aero on
            thrust_aero = out / f"{name}.thrust-aero.vehicle.json"
            run([str(propid), "replay", "--log", csv, "--thrust-aero-out", str(thrust_aero), "--no-progress"])
            for label, extra in (("gyro", ["--aiding", "gyro"]), ("default", []),
                                 ("gyro_corrected", ["--aiding", "gyro", "--vehicle", str(corrected),
                                                     "--aero-damping", "auto"]),
                                 ("default_thrust_aero", ["--vehicle", str(thrust_aero), "--thrust-aero", "on"])):
                path = out / f"{name}.replay-{label}.json"
                run([str(propid), "replay", "--log", csv, "--json", str(path), "--no-progress"] + extra)
                replays[label] = score_replay(json.loads(path.read_text()), truth)
            results[name] = {"flight": {"vehicle": vehicle, "aero": aero, "trajectory": traj,
                                        "log_rate_hz": log_rate, "esc_rate_hz": esc_rate, "seed": seed,
                                        "duration_s": args.duration},
                             "gap": gaps["default"], "gap_gyro_bias_attitude": gaps["-gyro-bias-attitude"],
                             "replay": replays, "thrust_aero_fit": thrust_aero_fit(thrust_aero, truth),
                             "wall_s": round(time.time() - t0, 1)}
    except RuntimeError as error:
        print(f"xsim: error: {error}", file=sys.stderr)
        return 1

    print_table(results)
    result_path.parent.mkdir(parents=True, exist_ok=True)
    result_path.write_text(json.dumps({"simulator": "rotorpy", "flights": results}, indent=2) + "\n")
    say(f"wrote {result_path}")
    return 0


def fmt(value, spec=".3f"):
    return "-" if value is None else format(value, spec)


def print_table(results: dict) -> None:
    head = ("flight", "gap verdict (significant)", "expected", "ok", "--gyro-bias attitude", "ok",
            "kf thr/roll/pitch, km yaw / truth",
            "fit ok", "replay gyro: fleet kf, max|kf err| sd, max|km err| sd", "ok",
            "gap's file: fleet kf", "+accel: fleet kf, thrust-aero on")
    rows = []
    for name, r in results.items():
        g, ga, rep = r["gap"], r["gap_gyro_bias_attitude"], r["replay"]["gyro"]
        fit = g["base_fit_after_ratio"] if r["flight"]["aero"] == "on" else g["base_fit_ratio"]
        rows.append((
            name, f"{g['verdict']} ({', '.join(g['significant']) or '-'})", "/".join(g["expected_ids"]),
            "yes" if g["verdict_right"] else "NO",
            f"{ga['verdict']} ({', '.join(ga['significant']) or '-'})", "yes" if ga["verdict_right"] else "NO",
            "/".join(fmt(fit[k]) for k in ("kf_thrust", "kf_roll", "kf_pitch", "km_yaw")),
            "yes" if g["base_fit_right"] else "NO",
            f"{rep['fleet_kf_ratio']:.3f}, {max(abs(s) for s in rep['kf_error_sigmas']):.1f}, "
            f"{max(abs(s) for s in rep['km_error_sigmas']):.1f}",
            ("yes" if rep["right"] else "NO") if r["flight"]["aero"] == "off" else "not judged",
            f"{r['replay']['gyro_corrected']['fleet_kf_ratio']:.3f}",
            f"{r['replay']['default']['fleet_kf_ratio']:.3f} -> {r['replay']['default_thrust_aero']['fleet_kf_ratio']:.3f}"))
    widths = [max(len(str(x)) for x in col) for col in zip(head, *rows)]
    for row in (head, *rows):
        print("  ".join(str(x).ljust(w) for x, w in zip(row, widths)))


if __name__ == "__main__":
    sys.exit(main())
