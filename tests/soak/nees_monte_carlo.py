#!/usr/bin/env python3
"""The NEES of soak clean flights over Monte-Carlo seeds (docs/reliability.md, "The NEES
sample by sample").

A soak flight is one draw of the truth and of the sensor noise: its share of NEES samples
in band says little when its error settles early (a hover's NEES is the same draw at every
sample). This tool flies each selected clean case of a soak plan (tests/soak/soak.py's
command, mode filter, the matched tuning) again with RUNS other seeds (`--seed`, which
draws the truth and the noise anew; vehicle, trajectory, duration and tuning the case's),
each with `propid_sitl --nees-dump`, and reports per case:

- the share in band of every run (the filter's own P) and its mean NEES per dof;
- at a few times: the mean over the runs of the NEES per dof, whole and per block (kf, km,
  gyro biases, each with its own covariance block), and the ratio of the error's
  Monte-Carlo second moment to the filter's mean variance per element of the kept bases
  (kf: roll- and pitch-torque combinations first, km: the yaw combination first; < 1:
  the filter's sigma too large there);
- the share in band a consistent estimator would score on the same errors: each run's
  error normalised by the Monte-Carlo covariance of the other runs' errors at the same
  time (their second moment), against that statistic's own 95 % interval (Hotelling's T^2
  for a covariance estimated from RUNS - 1 draws, simulated); it needs RUNS > dof + 1.

With several cases, the plan's pooled share (the soak's figure: samples in band over all
samples) is resampled with one run per case: its mean and the share of resamples at or
above 90 %, for the filter's P and for the consistent estimator.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shlex
import subprocess
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import rate_noise_rule  # noqa: E402  (the soak's loader)
from propid.errors import UserError  # noqa: E402
from propid.outputs import write_text  # noqa: E402

Z95 = 1.959964
REPORT_TIMES_S = (0.5, 1.0, 2.0, 5.0, 10.0, float("inf"))


def chi_square_quantile(k: int, z: float) -> float:
    """Wilson-Hilferty, as the SITL's honesty counter."""
    c = 2.0 / (9.0 * k)
    return k * (1.0 - c + z * np.sqrt(c)) ** 3


def read_dump(path: str) -> dict:
    """A --nees-dump file: the bases and per sample t, nees, error e (n) and covariance P (n x n)."""
    bases = {"kf": [], "km": []}
    header = None
    with open(path, encoding="utf-8") as handle:
        for skip, line in enumerate(handle):
            if line.startswith("# kf_basis_") or line.startswith("# km_basis_"):
                name, *values = line[2:].split(",")
                bases[name[:2]].append([float(v) for v in values])
            elif not line.startswith("#"):
                header = line.strip().split(",")
                break
    if header is None or header[:2] != ["t", "nees"]:
        raise UserError(f"{path}: not a propid_sitl --nees-dump file")
    n = sum(1 for name in header if name.startswith("e_"))
    data = np.loadtxt(path, delimiter=",", skiprows=skip + 1, ndmin=2)
    rows, cols = np.tril_indices(n)
    cov = np.zeros((len(data), n, n))
    cov[:, rows, cols] = data[:, 2 + n:]
    cov[:, cols, rows] = data[:, 2 + n:]
    return {"t": data[:, 0], "nees": data[:, 1], "e": data[:, 2:2 + n], "P": cov, "n": n,
            "kf_basis": np.array(bases["kf"]), "km_basis": np.array(bases["km"])}


def to_bases(dump: dict) -> tuple[np.ndarray, np.ndarray]:
    """The error and covariance with the kf and km blocks in the filter's kept bases."""
    rotors = len(dump["kf_basis"])
    transform = np.eye(dump["n"])
    transform[:rotors, :rotors] = dump["kf_basis"]
    transform[rotors:2 * rotors, rotors:2 * rotors] = dump["km_basis"]
    return dump["e"] @ transform.T, transform @ dump["P"] @ transform.T


def quadratic(e: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """e_k^T cov_k^-1 e_k for every sample k."""
    return np.einsum("ki,ki->k", e, np.linalg.solve(cov, e[..., None])[..., 0])


def hotelling_interval(dof: int, draws: int, rng: np.random.Generator, samples: int = 100_000) -> tuple[float, float]:
    """95 % interval of e^T S^-1 e, e ~ N(0, I) and S the second moment of `draws` others."""
    values = []
    for _ in range(samples // 2000):
        z = rng.standard_normal((draws, dof))
        second = z.T @ z / draws
        x = rng.standard_normal((2000, dof))
        values.append(quadratic(x, np.broadcast_to(second, (2000, dof, dof))))
    values = np.concatenate(values)
    return float(np.quantile(values, 0.025)), float(np.quantile(values, 0.975))


def fly(job: tuple) -> dict:
    sitl, case, extra, work = job
    soak = rate_noise_rule.load_soak()
    summary = os.path.join(work, f"c{case['case']}_s{case['seed']}.json")
    dump = os.path.join(work, f"c{case['case']}_s{case['seed']}.csv")
    proc = subprocess.run(soak.command(sitl, case, "filter", summary) + extra + ["--nees-dump", dump],
                          capture_output=True, text=True)
    if proc.returncode != 0 or not os.path.exists(dump):
        return {"seed": case["seed"], "error": f"exit {proc.returncode}: {proc.stderr.strip()[-300:]}"}
    honesty = json.loads(Path(summary).read_text()).get("honesty", {})
    return {"seed": case["seed"], "dump": dump, "in_band": int(honesty.get("nees_in_bounds", 0)),
            "samples": int(honesty.get("nees_samples", 0))}


def case_report(case: dict, runs: list[dict], rng: np.random.Generator) -> dict:
    dumps = [read_dump(run["dump"]) for run in runs]
    length = min(len(d["t"]) for d in dumps)
    n = dumps[0]["n"]
    rotors = len(dumps[0]["kf_basis"])
    lower, upper = chi_square_quantile(n, -Z95), chi_square_quantile(n, Z95)
    nees = np.array([d["nees"][:length] for d in dumps])
    usable = nees >= 0.0
    inside = usable & (nees >= lower) & (nees <= upper)
    own_share = 100.0 * inside.sum(axis=1) / usable.sum(axis=1)
    based = [to_bases({**d, "e": d["e"][:length], "P": d["P"][:length]}) for d in dumps]
    errors = np.array([b[0] for b in based])
    covs = np.array([b[1] for b in based])
    t = dumps[0]["t"][:length]
    names = (["kf_roll", "kf_pitch"] + [f"kf_rest_{i}" for i in range(2, rotors)] + ["km_yaw"]
             + [f"km_rest_{i}" for i in range(1, rotors)] + ["bias_x", "bias_y", "bias_z"]
             + ["torque_scale"] * (n - 2 * rotors - 3))
    blocks = {"kf": list(range(rotors)), "km": list(range(rotors, 2 * rotors)), "bias": [2 * rotors, 2 * rotors + 1, 2 * rotors + 2]}
    second_all = np.einsum("rki,rkj->kij", errors, errors)
    at_times = []
    for wanted in REPORT_TIMES_S:
        k = int(np.argmin(np.abs(t - min(wanted, t[-1]))))
        if at_times and at_times[-1]["t"] == round(float(t[k]), 3):
            continue
        ok = usable[:, k]
        mean_cov = covs[ok, k].mean(axis=0)
        second = second_all[k] / len(runs)
        at_times.append({
            "t": round(float(t[k]), 3),
            "nees_per_dof": round(float(nees[ok, k].mean() / n), 3),
            "in_band_pct": round(100.0 * float(inside[:, k].mean()), 1),
            "block_nees_per_dof": {name: round(float(np.mean(quadratic(errors[ok, k][:, idx], covs[ok, k][:, idx][:, :, idx])) / len(idx)), 3)
                                   for name, idx in blocks.items()},
            "second_moment_over_variance": {name: round(float(second[i, i] / mean_cov[i, i]), 3) for i, name in enumerate(names)},
        })
    out = {"case": case["case"], "vehicle": case["vehicle"], "trajectory": case["trajectory"],
           "sensors": case["sensors"], "duration_s": case["duration_s"], "dof": n, "runs": len(runs),
           "seeds": [run["seed"] for run in runs], "samples": [int(u.sum()) for u in usable],
           "own_in_band_pct": [round(float(s), 2) for s in own_share],
           "own_nees_per_dof": [round(float(np.mean(v[u]) / n), 3) for v, u in zip(nees, usable)],
           "at_times": at_times, "consistent_in_band_pct": None, "consistent_interval": None}
    if len(runs) - 1 > n + 1:
        lo, hi = hotelling_interval(n, len(runs) - 1, rng)
        shares = []
        for r in range(len(runs)):
            others = (second_all - np.einsum("ki,kj->kij", errors[r], errors[r])) / (len(runs) - 1)
            value = quadratic(errors[r], others)
            shares.append(round(100.0 * float(np.mean((value >= lo) & (value <= hi))), 2))
        out["consistent_in_band_pct"] = shares
        out["consistent_interval"] = [round(lo, 3), round(hi, 3)]
    return out


def pooled(reports: list[dict], rng: np.random.Generator, draws: int = 20_000) -> dict:
    """The plan's pooled share with one run per case, resampled."""
    out = {}
    for key in ("own_in_band_pct", "consistent_in_band_pct"):
        usable = [r for r in reports if r[key] is not None]
        if not usable:
            continue
        picks = [rng.integers(0, r["runs"], draws) for r in usable]
        inside = sum(np.array(r[key])[p] * np.array(r["samples"])[p] for r, p in zip(usable, picks))
        total = sum(np.array(r["samples"])[p] for r, p in zip(usable, picks))
        share = inside / total
        out[key.replace("_in_band_pct", "")] = {"cases": len(usable), "mean_pct": round(float(share.mean()), 2),
                                               "p5_pct": round(float(np.quantile(share, 0.05)), 2),
                                               "p95_pct": round(float(np.quantile(share, 0.95)), 2),
                                               "at_least_90_pct_of_resamples": round(100.0 * float(np.mean(share >= 90.0)), 1)}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    rate_noise_rule.add_plan_arguments(parser)
    parser.add_argument("--case", type=int, action="append",
                        help="a clean case of the plan (repeatable; default: every clean case of --sensors)")
    parser.add_argument("--sensors", choices=("all", "default", "paper"), default="paper",
                        help="without --case: the clean cases with this sensor set (default paper)")
    parser.add_argument("--runs", type=int, default=50, help="Monte-Carlo runs per case (default 50)")
    parser.add_argument("--first-seed", type=int, default=2001,
                        help="flight seed of the first run (default 2001; the plan's own seeds are 1000 + case)")
    parser.add_argument("--default-args", default="", help="extra propid_sitl options for default-sensor cases")
    parser.add_argument("--paper-args", default="", help="extra propid_sitl options for paper-sensor cases")
    parser.add_argument("--jobs", type=int, default=2, help="flights in parallel (default 2)")
    parser.add_argument("--out", help="write the report here (JSON)")
    args = parser.parse_args(argv)
    rate_noise_rule.check_sitl_and_out(parser, args)
    if args.runs < 2 or args.jobs < 1 or args.steps <= 0:
        parser.error("--runs must be >= 2, --jobs >= 1 and --steps > 0")
    import nees_options  # noqa: E402  (the plan's clean cases)
    cases = nees_options.clean_cases(args.seed, args.steps)
    if args.case:
        known = {c["case"] for c in cases}
        missing = sorted(set(args.case) - known)
        if missing:
            parser.error(f"--case {missing[0]}: not a clean case of plan {args.seed} (clean: {sorted(known)})")
        cases = [c for c in cases if c["case"] in args.case]
    else:
        cases = [c for c in cases if args.sensors in ("all", c["sensors"])]
    extra = {"default": shlex.split(args.default_args), "paper": shlex.split(args.paper_args)}
    try:
        from tqdm import tqdm
    except ImportError:
        tqdm = None
    rng = np.random.default_rng(0)
    reports = []
    with tempfile.TemporaryDirectory(prefix="nees-mc-") as work, ProcessPoolExecutor(args.jobs) as pool:
        bar = tqdm(total=len(cases) * args.runs, unit="flight", desc=f"plan {args.seed}", file=sys.stderr) if tqdm else None
        for case in cases:
            jobs = [(args.sitl, {**case, "seed": args.first_seed + k}, extra[case["sensors"]], work)
                    for k in range(args.runs)]
            runs = []
            for run in pool.map(fly, jobs):
                runs.append(run)
                if bar:
                    bar.update(1)
            failed = [r for r in runs if "error" in r]
            if failed:
                print(f"nees_monte_carlo: case {case['case']} seed {failed[0]['seed']}: {failed[0]['error']}",
                      file=sys.stderr)
                return 1
            report = case_report(case, runs, rng)
            for run in runs:
                os.remove(run["dump"])
            reports.append(report)
            own = np.array(report["own_in_band_pct"])
            consistent = report["consistent_in_band_pct"]
            line = (f"case {case['case']} {case['vehicle']} {case['trajectory']} {case['duration_s']} s: "
                    f"own P in band {own.mean():.1f} % (runs < 90 %: {int(np.sum(own < 90))} of {len(own)}), "
                    f"NEES/dof {np.mean(report['own_nees_per_dof']):.2f}")
            if consistent is not None:
                line += f"; consistent sigma {np.mean(consistent):.1f} % (runs < 90 %: {int(np.sum(np.array(consistent) < 90))})"
            (bar.write if bar else print)(line)
        if bar:
            bar.close()
    out = {"plan_seed": args.seed, "runs": args.runs, "first_seed": args.first_seed,
           "default_args": args.default_args, "paper_args": args.paper_args,
           "pooled": pooled(reports, rng), "cases": reports}
    if args.out:
        write_text(args.out, json.dumps(out, indent=1) + "\n")
    print(json.dumps(out["pooled"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
