#!/usr/bin/env python3
"""The accelerometer row's slow model error, measured on the damage bench's flights
with effects, and the Gauss-Markov description it calls for (docs/math.md §9, "The
row's model error"; docs/damage.md, "H read by the paired rule").

The filter's accelerometer row is `f_z = sum_i kf_i u_i / m + b_z (+ e) + v`. With the
true coefficients and the sensor's true bias, what is left of the logged z specific
force is the row's own error as the filter sees it:

    r(t) = acc_z(t) - sum_i true_kf_i(t) omega_i(t)^2 / m - true_accel_bias_z

with `omega_i` the reported (telemetry) speeds the filter's row uses. Its white part
is the sensor's noise; what matters for the z bias is the slow part (the vertical
forces the row leaves out, the decoded speeds' error). The rule, fixed before it was
run: the pooled non-centred autocovariance over every flight,
`C(L) = sum r(t) r(t + L) / count` for lags 20 ms .. 2 s (from 20 ms on, the white
noise and the telemetry's millisecond errors drop out), from 0.5 s into each flight;
`sigma^2 = C(20 ms)`; `tau` from the least-squares fit through the origin of
`ln(C(L) / C(20 ms)) = -(L - 20 ms) / tau` over the lags where the ratio is above
0.05. The flights: the undamaged flights with effects of `propid damage-bench
--seed S` (its flight list and command for each, Filter mode, with a log).

    tests/soak/accel_error_rule.py --seed 2000 --seed 3000 [--sitl build/host/sitl/propid_sitl]
        [--out FILE.json] [--workers 1]
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import subprocess
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from propid import damage_bench
from propid.errors import UserError
from propid.outputs import check_writable, write_text
from tqdm import tqdm

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
SKIP_S = 0.5           # the take-off's first half second left out
FIRST_LAG_S = 0.02     # from here on the white noise drops out
LAST_LAG_S = 2.0
FIT_FLOOR = 0.05       # lags whose normalised autocovariance is above it enter the fit


def row_error(log_csv: Path, summary: dict, mass: float) -> tuple[np.ndarray, float]:
    """r(t) of one flight from SKIP_S on, and its sample period [s]."""
    with open(log_csv, newline="") as handle:
        rows = list(csv.DictReader(row for row in handle if not row.startswith("#")))
    if not rows:
        raise UserError(f"{log_csv}: no rows")
    rotors = sum(1 for key in rows[0] if key.startswith("true_kf_"))
    bias = float(summary["accel"]["true_bias_z"])
    times, values = [], []
    for row in rows:
        acc = row.get("acc_z", "")
        speeds = [row.get(f"omega_{i}", "") for i in range(1, rotors + 1)]
        if acc == "" or any(s == "" for s in speeds):
            continue
        thrust = sum(float(row[f"true_kf_{i}"]) * float(speeds[i - 1]) ** 2 for i in range(1, rotors + 1))
        times.append(float(row["t"]))
        values.append(float(acc) - thrust / mass - bias)
    t = np.asarray(times)
    r = np.asarray(values)
    if t.size < 2:
        raise UserError(f"{log_csv}: fewer than two rows with acc_z and every rotor speed")
    period = float(np.median(np.diff(t)))
    return r[t >= t[0] + SKIP_S], period


def _fly(args: tuple) -> dict:
    config, spec, work = args
    log = Path(work) / f"f{spec.index}.csv"
    summary_path = Path(work) / f"f{spec.index}.json"
    cmd = damage_bench._command(config, spec, "filter", log, summary_path)
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode not in (0, 2):  # 2: the flight diverged (still measured)
        raise UserError(f"flight {spec.index}: propid_sitl exit {done.returncode}: {done.stderr.strip()[:200]}")
    summary = json.loads(summary_path.read_text())
    vehicle = json.loads(Path(str(log)[:-4] + ".vehicle.json").read_text())
    r, period = row_error(log, summary, float(vehicle["mass"]))
    log.unlink()
    return {"index": spec.index, "seed": spec.seed, "effects": spec.effects, "period": period,
            "r": r.tolist()}


def autocovariance(series: list[np.ndarray], lags: np.ndarray) -> np.ndarray:
    """Pooled non-centred autocovariance at the given lags (samples)."""
    out = np.zeros(lags.size)
    for k, lag in enumerate(lags):
        total, count = 0.0, 0
        for r in series:
            if r.size > lag:
                total += float(np.dot(r[: r.size - lag], r[lag:]))
                count += r.size - lag
        out[k] = total / count if count else math.nan
    return out


def describe(series: list[np.ndarray], period: float) -> dict:
    """sigma and tau by the rule (module docstring)."""
    first = max(1, int(round(FIRST_LAG_S / period)))
    last = int(round(LAST_LAG_S / period))
    lags = np.arange(first, last + 1, max(1, int(round(0.01 / period))))
    cov = autocovariance(series, lags)
    ratio = cov / cov[0]
    keep = ratio > FIT_FLOOR
    x = (lags[keep] - lags[0]) * period
    y = np.log(ratio[keep])
    slope = float(np.dot(x, y) / np.dot(x, x)) if np.dot(x, x) > 0 else 0.0
    tau = -1.0 / slope if slope < 0 else math.inf
    return {"sigma": math.sqrt(max(float(cov[0]), 0.0)), "tau": tau, "lags_s": (lags * period).tolist(),
            "normalised_autocovariance": ratio.tolist(), "fitted_lags": int(keep.sum())}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, action="append", required=True,
                        help="damage-bench base seed whose flights with effects are flown (repeatable)")
    parser.add_argument("--sitl", type=Path, default=REPO / "build/host/sitl/propid_sitl")
    parser.add_argument("--undamaged", type=int, default=100, help="the bench's flights with effects per seed")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", type=Path, help="write the figures as JSON")
    args = parser.parse_args(argv)
    try:
        if not args.sitl.is_file():
            raise UserError(f"{args.sitl}: no SITL binary (make sitl)")
        if args.out:
            check_writable(args.out)
        jobs = []
        with tempfile.TemporaryDirectory() as work:
            for seed in args.seed:
                config = damage_bench.BenchConfig(sitl=args.sitl, out_dir=Path(work), base_seed=seed,
                                                  undamaged=args.undamaged)
                jobs += [(config, spec, work) for spec in damage_bench.flight_specs(config) if spec.effects]
            with ProcessPoolExecutor(max_workers=max(1, args.workers)) as pool:
                flights = list(tqdm(pool.map(_fly, jobs), total=len(jobs), desc="flights", unit="flight"))
        periods = {f["period"] for f in flights}
        period = float(np.median(list(periods)))
        series = [np.asarray(f["r"]) for f in flights]
        result = describe(series, period)
        per_flight = [{"index": f["index"], "seed": f["seed"], "effects": f["effects"],
                       "mean": float(np.mean(f["r"])), "rms": float(np.sqrt(np.mean(np.square(f["r"]))))}
                      for f in flights]
        result.update({"seeds": args.seed, "flights": len(flights), "sample_period_s": period,
                       "per_flight": per_flight})
        print(f"{len(flights)} flights with effects (seeds {', '.join(map(str, args.seed))}): "
              f"sigma {result['sigma']:.4f} m/s^2, tau {result['tau']:.3f} s "
              f"({result['fitted_lags']} lags fitted)")
        means = sorted(abs(f["mean"]) for f in per_flight)
        print(f"per-flight |mean| median {means[len(means) // 2]:.4f}, p95 {means[int(0.95 * (len(means) - 1))]:.4f} m/s^2")
        if args.out:
            write_text(args.out, json.dumps(result, indent=1) + "\n")
    except UserError as error:
        print(f"accel_error_rule: {error}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
