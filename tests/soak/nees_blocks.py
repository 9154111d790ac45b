#!/usr/bin/env python3
"""Where a flight's NEES sits: per block and per information direction, with the loading's
fading memory (docs/reliability.md, "Why the exact-speed flights are underconfident").

Reads `propid_sitl --nees-dump` files (the error of kf, km and the gyro biases and their
covariance at every NEES sample) and reports, over the samples from --from seconds on whose
covariance is positive definite:

- the NEES per degree of freedom, whole and per block (kf, km, biases, each with its own
  covariance block), over the flight and in --windows equal time spans;
- the NEES per information direction: the eigenvectors of the covariance scaled by the prior
  (the soak's matched priors unless given), binned by eigenvalue, i.e. by the share of the prior
  variance the flight has left in that direction; per bin the mean of the squared normalised
  error (1 for an honest sigma, about 0.5 where the variance is held by a fictitious random
  walk the plant does not have) and the number of directions per sample;
- the fading memory of the firmware's `1 + eps` loading (docs/math.md §2) along the three
  best-determined directions: the loading, eps times each kept-basis variance (the drag
  coefficients every second step), projected on the direction and divided by its variance,
  per second at the gyro rate; a rate of 1/s forgets that direction's information in about
  a second.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from nees_monte_carlo import read_dump, to_bases  # noqa: E402  (the dump's reader and the kept bases)
from propid.errors import UserError  # noqa: E402
from propid.outputs import write_text  # noqa: E402

FLOAT32_EPS = 2.0 ** -23  # PROPID_VAR_LOADING
DRAG_LOADING_SHARE = 0.5  # the drag coefficients are loaded every second step (propid_internal.h)
PRIOR_COEFF_STD = 0.2 / math.sqrt(3.0)  # the soak's matched prior: U(1 - 0.2, 1 + 0.2) (soak.py)
PRIOR_BIAS_STD = math.radians(1.0) / math.sqrt(3.0)  # U(-1, 1) deg/s (soak.py)
BIN_EDGES = (0.0, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, math.inf)  # eigenvalue over the prior's
FADING_DIRECTIONS = 3


def block_nees(error: np.ndarray, cov: np.ndarray) -> float | None:
    """Mean of e^T P^-1 e over the samples whose block reads back positive definite, per degree
    of freedom (the dump's nine digits can leave a nearly singular block indefinite); None if none does."""
    definite = np.linalg.eigvalsh(cov)[:, 0] > 0.0
    if not definite.any():
        return None
    error, cov = error[definite], cov[definite]
    solved = np.linalg.solve(cov, error[..., None])[..., 0]
    return round(float(np.mean(np.einsum("ki,ki->k", error, solved)) / error.shape[1]), 4)


def direction_bins(error: np.ndarray, cov: np.ndarray, prior_std: np.ndarray) -> list[dict]:
    """Squared normalised error per eigen-direction of the prior-scaled covariance, binned by eigenvalue."""
    scaled_cov = cov / np.outer(prior_std, prior_std)[None]
    values, vectors = np.linalg.eigh(scaled_cov)
    projected = np.einsum("kij,ki->kj", vectors, error / prior_std[None])
    z_squared = projected ** 2 / values
    bins = []
    for low, high in zip(BIN_EDGES[:-1], BIN_EDGES[1:]):
        inside = (values >= low) & (values < high)
        if inside.any():
            bins.append({"eigenvalue_over_prior": [low, None if math.isinf(high) else high],
                         "mean_z_squared": round(float(z_squared[inside].mean()), 4),
                         "directions_per_sample": round(float(inside.sum()) / len(values), 2)})
    return bins


def fading_per_s(cov_in_bases: np.ndarray, rotors: int, gyro_rate_hz: float) -> list[float]:
    """Median over the samples of the loading's relative rate along the best-determined directions."""
    share = np.ones(cov_in_bases.shape[1])
    share[rotors:2 * rotors] = DRAG_LOADING_SHARE
    values, vectors = np.linalg.eigh(cov_in_bases)
    loading = FLOAT32_EPS * share[None] * np.diagonal(cov_in_bases, axis1=1, axis2=2)
    per_step = np.einsum("kij,ki->kj", vectors ** 2, loading) / values
    count = min(FADING_DIRECTIONS, cov_in_bases.shape[1])
    return [float(f"{float(np.median(per_step[:, k])) * gyro_rate_hz:.6g}") for k in range(count)]


def analyse(path: str, t_from: float = 0.5, prior_coeff_std: float = PRIOR_COEFF_STD,
            prior_bias_std: float = PRIOR_BIAS_STD, gyro_rate_hz: float = 500.0, windows: int = 1) -> dict:
    dump = read_dump(path)
    n, rotors = dump["n"], len(dump["kf_basis"])
    if n != 2 * rotors + 3:
        raise UserError(f"{path}: {n} states; only kf, km and biases (no torque-scale state) are split here")
    usable = (dump["nees"] >= 0.0) & (dump["t"] >= t_from)
    if not usable.any():
        raise UserError(f"{path}: no positive definite NEES sample from {t_from} s on")
    error, cov = dump["e"][usable], dump["P"][usable]
    blocks = {"kf": slice(0, rotors), "km": slice(rotors, 2 * rotors), "bias": slice(2 * rotors, n)}
    prior_std = np.array([prior_coeff_std] * (2 * rotors) + [prior_bias_std] * 3)
    _, cov_in_bases = to_bases({**dump, "e": error, "P": cov})
    nees, times = dump["nees"][usable], dump["t"][usable]
    edges = np.linspace(times[0], times[-1], windows + 1)
    over_time = []
    for k in range(windows):
        part = (times >= edges[k]) & ((times < edges[k + 1]) if k + 1 < windows else (times <= edges[k + 1]))
        if part.any():
            over_time.append({"from_s": round(float(edges[k]), 3), "to_s": round(float(edges[k + 1]), 3),
                              "nees_per_dof": round(float(np.mean(nees[part])) / n, 4),
                              **{name: block_nees(error[part][:, s], cov[part][:, s, s])
                                 for name, s in blocks.items()}})
    return {"file": path, "samples": int(usable.sum()), "dof": n,
            "nees_per_dof": round(float(np.mean(nees)) / n, 4),
            "block_nees_per_dof": {name: block_nees(error[:, s], cov[:, s, s]) for name, s in blocks.items()},
            "over_time": over_time,
            "directions": direction_bins(error, cov, prior_std),
            "fading_per_s": fading_per_s(cov_in_bases, rotors, gyro_rate_hz)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dumps", nargs="+", metavar="DUMP.csv", help="propid_sitl --nees-dump files")
    parser.add_argument("--from", dest="t_from", type=float, default=0.5,
                        help="leave out the samples before this time [s] (default 0.5)")
    parser.add_argument("--prior-coeff-std", type=float, default=PRIOR_COEFF_STD,
                        help=f"relative prior std of kf and km (default the soak's, {PRIOR_COEFF_STD:.4f})")
    parser.add_argument("--prior-bias-std", type=float, default=PRIOR_BIAS_STD,
                        help=f"prior std of the gyro biases [rad/s] (default the soak's, {PRIOR_BIAS_STD:.5f})")
    parser.add_argument("--gyro-rate", type=float, default=500.0,
                        help="gyro sample rate [Hz] the loading is applied at (default 500, the paper's sensors)")
    parser.add_argument("--windows", type=int, default=1,
                        help="also split the samples into this many equal time spans, NEES/dof per block in each "
                             "(default 1)")
    parser.add_argument("--out", help="write the figures here (JSON)")
    args = parser.parse_args(argv)
    if not (args.prior_coeff_std > 0.0 and args.prior_bias_std > 0.0 and args.gyro_rate > 0.0):
        parser.error("--prior-coeff-std, --prior-bias-std and --gyro-rate must be > 0")
    if not 1 <= args.windows <= 1000:
        parser.error("--windows must be in 1..1000")
    try:
        results = [analyse(path, args.t_from, args.prior_coeff_std, args.prior_bias_std, args.gyro_rate, args.windows)
                   for path in args.dumps]
    except (UserError, OSError, ValueError) as exc:
        print(f"nees_blocks: {exc}", file=sys.stderr)
        return 2
    for result in results:
        blocks = {name: "-" if v is None else f"{v:.3f}" for name, v in result["block_nees_per_dof"].items()}
        print(f"{result['file']}: {result['samples']} samples, NEES/dof {result['nees_per_dof']:.3f}; "
              f"kf {blocks['kf']}, km {blocks['km']}, biases {blocks['bias']}; "
              f"fading of the best-determined directions {result['fading_per_s']} per s")
        if args.windows > 1:
            for part in result["over_time"]:
                shown = {name: "-" if part[name] is None else f"{part[name]:.3f}" for name in ("kf", "km", "bias")}
                print(f"  {part['from_s']:.1f}-{part['to_s']:.1f} s: NEES/dof {part['nees_per_dof']:.3f}; "
                      f"kf {shown['kf']}, km {shown['km']}, biases {shown['bias']}")
        for group in result["directions"]:
            low, high = group["eigenvalue_over_prior"]
            print(f"  eigenvalue/prior {low:g}-{'inf' if high is None else f'{high:g}'}: "
                  f"mean z^2 {group['mean_z_squared']:.3f} over {group['directions_per_sample']} directions")
    if args.out:
        write_text(args.out, json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
