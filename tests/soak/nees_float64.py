#!/usr/bin/env python3
"""The NEES of a soak plan's exact-speed clean flights with and without the float32 loadings
(docs/reliability.md, "The loading's cost, measured in float64").

Flies each paper-sensor clean case of a soak plan once (tests/soak/soak.py's command, mode
filter, the matched tuning) with a log, reads the flight's rate process noise from that log
(rate_noise_rule.derive) unless --rate-noise gives one, and replays the log (at each 500 Hz
row the rotor speeds, then the gyro sample, as the SITL pushes them) through three filters
with that rate noise and the soak's other settings:

- c: the C filter (propid.cfilter, float32 with its loadings);
- float64: the float64 reference of the same algorithm, loadings included;
- float64_unloaded: the same reference without the loadings (`ReferenceFilter(...,
  loadings=False)`: the plain EKF of the same model, which float64 can carry);
- float64_gyro: the reference with the loadings the same algorithm takes with the rate kept in the
  gyro's coordinate s = omega + b (`ReferenceFilter(..., rate_coordinate="gyro")`; only with
  --filters, docs/reliability.md, "The rate in the gyro's coordinate, measured in float64").

The NEES of kf, km and the gyro biases against the log's truth every 10th row (the SITL's
50 Hz), in its 95 % band as the SITL counts it (Wilson-Hilferty; a block that is not
positive definite is not counted). Prints and writes (--out) the shares in band, below and
above per filter, pooled over the flights and per flight. Only exact speeds: with the
default sensors the gyro runs at 1 kHz and the log's rows hold every second sample.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import rate_noise_rule  # noqa: E402  (the soak's loader, the derived rate noise, the plan options)
from propid.cfilter import CFilter, FilterConfig  # noqa: E402
from propid.errors import UserError  # noqa: E402
from propid.flightlog import read_table, read_vehicle  # noqa: E402
from propid.outputs import write_text  # noqa: E402
from propid.reference_filter import ReferenceFilter  # noqa: E402

FILTERS = ("c", "float64", "float64_unloaded")  # the default set
ALL_FILTERS = FILTERS + ("float64_gyro",)
NEES_EVERY = 10  # rows between NEES samples (sitl/app/honesty.c: HONESTY_NEES_EVERY)
PAPER_GYRO_RATE_HZ = 500.0  # sitl/sensors/imu.c, the paper's IMU
GYRO_NOISE_DENSITY = 0.014 * math.pi / 180.0  # the simulated gyro's (BMI088 datasheet), rad/s/sqrt(Hz)
Z95 = 1.959964


def chi_square_quantile(k: int, z: float) -> float:
    """Wilson-Hilferty, as the SITL's honesty counter."""
    c = 2.0 / (9.0 * k)
    return k * (1.0 - c + z * math.sqrt(c)) ** 3


def replay_config(vehicle_file: str, preset: str, rate_noise: float) -> FilterConfig:
    """The filter the soak's matched tuning configures for a paper-sensor flight
    (sitl/app/sim_setup.c with tests/soak/soak.py's matched_filter), at rate_noise."""
    soak = rate_noise_rule.load_soak()
    tau_m, speed_max = rate_noise_rule.MOTORS[preset.split("-")[0]]
    coeff_std = soak.COEFF_SPREAD / math.sqrt(3.0)
    return FilterConfig.from_vehicle(
        read_vehicle(vehicle_file), thrust_coeff_rel_std0=coeff_std, drag_coeff_rel_std0=coeff_std,
        gyro_bias_std0=soak.GYRO_BIAS_MAX / math.sqrt(3.0), thrust_coeff_rel_walk=0.0, drag_coeff_rel_walk=0.0,
        gyro_bias_walk=soak.GYRO_BIAS_WALK["paper"], gyro_noise_density=GYRO_NOISE_DENSITY,
        gyro_sample_rate_hz=PAPER_GYRO_RATE_HZ, rate_process_noise=rate_noise, max_rotor_speed=1.5 * speed_max,
        motor_time_constant=tau_m, inertia_rel_std=soak.plan_inertia_rel_rms())


def make_filter(name: str, config: FilterConfig):
    if name == "c":
        return CFilter(config)
    if name == "float64_gyro":
        return ReferenceFilter(config, rate_coordinate="gyro")
    return ReferenceFilter(config, loadings=(name == "float64"))


def replay_nees(log: str, config: FilterConfig, name: str) -> dict:
    """The filter `name` over the log's rows; NEES counts against the log's truth."""
    table = read_table(log)
    n_rot = config.rotor_count
    def stack(fmt: str, keys) -> np.ndarray:
        return np.stack([table[fmt.format(k)] for k in keys], axis=1)
    t = table["t"]
    gyro, speeds = stack("gyro_{}", "xyz"), stack("omega_{}", range(1, n_rot + 1))
    truth = np.concatenate([stack("true_kf_{}", range(1, n_rot + 1)) / np.array(config.thrust_coeff_nominal),
                            stack("true_km_{}", range(1, n_rot + 1)) / np.array(config.drag_coeff_nominal),
                            stack("true_bg_{}", "xyz")], axis=1)
    dof = 2 * n_rot + 3
    lower, upper = chi_square_quantile(dof, -Z95), chi_square_quantile(dof, Z95)
    counts = {"samples": 0, "in_band": 0, "below": 0, "above": 0, "not_pd": 0}
    total = 0.0
    filt = make_filter(name, config)
    for k in range(len(t)):
        if np.all(np.isfinite(gyro[k])) and np.all(np.isfinite(speeds[k])):
            t_us = int(round(t[k] * 1e6))
            filt.push_rotor_speeds(t_us, speeds[k].tolist())
            filt.push_gyro(t_us, gyro[k].tolist())
        if k % NEES_EVERY != 0 or not np.all(np.isfinite(truth[k])):
            continue
        state, cov = filt.scaled_state()
        error = state[3:3 + dof] - truth[k]
        try:
            factor = np.linalg.cholesky(cov[3:3 + dof, 3:3 + dof])
        except np.linalg.LinAlgError:
            counts["not_pd"] += 1
            continue
        nees = float(np.sum(np.linalg.solve(factor, error) ** 2))
        counts["samples"] += 1
        total += nees
        side = "below" if nees < lower else ("above" if nees > upper else "in_band")
        counts[side] += 1
    counts["nees_per_dof"] = round(total / max(1, counts["samples"]) / dof, 4)
    return counts


def fly_case(job: tuple) -> dict:
    sitl, case, rate_noise, filters = job
    soak = rate_noise_rule.load_soak()
    with tempfile.TemporaryDirectory(prefix="nees-float64-") as work:
        log, summary = os.path.join(work, "flight.csv"), os.path.join(work, "flight.json")
        proc = subprocess.run(soak.command(sitl, case, "filter", summary) + ["--log", log],
                              capture_output=True, text=True)
        in_loop = rate_noise_rule.nees_figures(summary, proc)
        if proc.returncode != 0 or not os.path.exists(log):
            return {"case": case, "error": f"exit {proc.returncode}: {proc.stderr.strip()[-300:]}"}
        vehicle_file = log[:-4] + ".vehicle.json"
        q = rate_noise if rate_noise is not None else rate_noise_rule.derive(
            log, vehicle_file, case["vehicle"], "paper")["q_rate"]
        config = replay_config(vehicle_file, case["vehicle"], q)
        return {"case": case, "rate_noise": q, "in_loop_soak_tuning": in_loop,
                **{name: replay_nees(log, config, name) for name in filters}}


def share(part: int, whole: int) -> float | None:
    return round(100.0 * part / whole, 2) if whole else None


def pooled(results: list[dict], filters: tuple = FILTERS) -> dict:
    """Per filter: the shares of all flights' NEES samples in band, below and above, and the
    flights under 90 % in band."""
    out = {}
    for name in filters:
        flights = [r[name] for r in results if name in r]
        samples = sum(f["samples"] for f in flights)
        out[name] = {"in_band_pct": share(sum(f["in_band"] for f in flights), samples),
                     "below_pct": share(sum(f["below"] for f in flights), samples),
                     "above_pct": share(sum(f["above"] for f in flights), samples),
                     "flights": len(flights),
                     "flights_under_90_pct": sum(1 for f in flights if f["samples"] and
                                                 100.0 * f["in_band"] < 90.0 * f["samples"]),
                     "not_pd_samples": sum(f["not_pd"] for f in flights)}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    rate_noise_rule.add_plan_arguments(parser)
    parser.add_argument("--case", type=int, action="append",
                        help="a paper-sensor clean case of the plan (repeatable; default: all of them)")
    parser.add_argument("--rate-noise", type=float,
                        help="replay at this rate process noise [rad/s^2/sqrt(Hz)] (default: each flight's "
                             "derived value, rate_noise_rule.derive)")
    parser.add_argument("--filters", default=",".join(FILTERS),
                        help=f"comma-separated, of {', '.join(ALL_FILTERS)} (default: {','.join(FILTERS)})")
    parser.add_argument("--jobs", type=int, default=2, help="flights in parallel (default 2)")
    parser.add_argument("--out", help="write the figures and the per-flight results here (JSON)")
    args = parser.parse_args(argv)
    filters = tuple(name.strip() for name in args.filters.split(",") if name.strip())
    unknown = [name for name in filters if name not in ALL_FILTERS]
    if unknown or not filters:
        parser.error(f"--filters: {unknown[0] if unknown else 'none given'} is not one of {', '.join(ALL_FILTERS)}")
    rate_noise_rule.check_sitl_and_out(parser, args)
    if args.jobs < 1 or args.steps <= 0:
        parser.error("--jobs must be >= 1 and --steps > 0")
    if args.rate_noise is not None and not (math.isfinite(args.rate_noise) and args.rate_noise > 0.0):
        parser.error("--rate-noise must be a positive number")
    import nees_options  # noqa: E402  (the plan's clean cases)
    cases = [c for c in nees_options.clean_cases(args.seed, args.steps) if c["sensors"] == "paper"]
    if args.case:
        known = {c["case"] for c in cases}
        missing = sorted(set(args.case) - known)
        if missing:
            parser.error(f"--case {missing[0]}: not a paper-sensor clean case of plan {args.seed} "
                         f"(those: {sorted(known)})")
        cases = [c for c in cases if c["case"] in args.case]
    try:
        from tqdm import tqdm
    except ImportError:  # the bar is a convenience
        tqdm = None
    jobs = [(args.sitl, case, args.rate_noise, filters) for case in cases]
    try:
        with ProcessPoolExecutor(args.jobs) as pool:
            iterator = pool.map(fly_case, jobs)
            if tqdm:
                iterator = tqdm(iterator, total=len(jobs), unit="flight", desc=f"plan {args.seed}", file=sys.stderr)
            results = list(iterator)
    except UserError as exc:
        print(f"nees_float64: {exc}", file=sys.stderr)
        return 1
    failed = [r for r in results if "error" in r]
    if failed:
        print(f"nees_float64: case {failed[0]['case']['case']}: {failed[0]['error']}", file=sys.stderr)
        return 1
    out = {"plan_seed": args.seed, "rate_noise": args.rate_noise if args.rate_noise is not None else "derived",
           "pooled": pooled(results, filters), "flights": results}
    if args.out:
        write_text(args.out, json.dumps(out, indent=1) + "\n")
    print(json.dumps({key: out[key] for key in ("plan_seed", "rate_noise", "pooled")}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
