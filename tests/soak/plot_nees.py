#!/usr/bin/env python3
"""Plot the NEES of the soak's fault-free, effect-free flights, one soak run per tuning.

Reads soak.json files written by `make soak` (their `nees_flights`) and draws,
per flight, the mean NEES divided by its degrees of freedom (log scale, with the
95 % chi-square interval of one sample shaded) and the share of samples inside
that interval. Example (docs/reliability.md):

  make soak SOAK_NEES_TUNING=library && cp build/results/soak.json /tmp/soak-library.json
  make soak && python tests/soak/plot_nees.py /tmp/soak-library.json build/results/soak.json \\
      --out docs/img/soak_nees.png
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def chi_square_quantile(k: float, z: float) -> float:
    """z-quantile of chi-square(k), Wilson-Hilferty (as the simulator's honesty metric)."""
    c = 2.0 / (9.0 * k)
    root = 1.0 - c + z * c ** 0.5
    return k * root ** 3


def load(path: str) -> list[dict]:
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise SystemExit(f"plot_nees: {path}: not a readable soak.json ({error})")
    flights = data.get("nees_flights")
    if not isinstance(flights, list) or not flights:
        raise SystemExit(f"plot_nees: {path}: no nees_flights (written by make soak)")
    return flights


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("soak_json", nargs="+", help="soak.json files (one per tuning)")
    parser.add_argument("--out", required=True, help="PNG to write")
    args = parser.parse_args(argv)
    runs = [load(path) for path in args.soak_json]

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_nees, ax_in) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
    dof = runs[0][0]["dof"] or 11
    width = 0.8 / len(runs)
    order = sorted(runs[0], key=lambda f: (f["sensors"], f["vehicle"], f["trajectory"], f["case"]))
    cases = [f["case"] for f in order]
    labels = [f'{f["vehicle"].replace("crazyflie", "cf").replace("hummingbird", "hb")} {f["trajectory"][:4]} '
              f'{"P" if f["sensors"] == "paper" else "D"}' for f in order]
    for r, flights in enumerate(runs):
        by_case = {f["case"]: f for f in flights}
        xs, nees, inside = [], [], []
        for i, case in enumerate(cases):
            f = by_case.get(case)
            if f is None or f["nees_mean"] is None:
                continue
            xs.append(i + (r - (len(runs) - 1) / 2) * width)
            nees.append(f["nees_mean"] / f["dof"])
            inside.append(f["in_bounds_pct"])
        total = sum(f["in_bounds_pct"] or 0.0 for f in flights) / len(flights)
        label = f'{flights[0]["tuning"]} tuning (flight mean of in-bounds: {total:.0f} %)'
        ax_nees.bar(xs, nees, width=width, label=label)
        ax_in.bar(xs, inside, width=width, label=label)
    low, high = chi_square_quantile(dof, -1.959964) / dof, chi_square_quantile(dof, 1.959964) / dof
    ax_nees.axhspan(low, high, color="0.85", zorder=0, label=f"95 % interval of one sample ({dof} dof)")
    ax_nees.axhline(1.0, color="0.4", lw=0.8)
    ax_nees.set_yscale("log")
    ax_nees.set_ylabel("mean NEES / dof")
    ax_nees.legend(fontsize=8, loc="upper left")
    ax_nees.set_title("Fault-free, effect-free soak flights: coefficients + gyro biases "
                      "(P = paper sensors, D = BMI088/DShot)", fontsize=10)
    ax_in.axhline(95.0, color="0.4", lw=0.8)
    ax_in.set_ylabel("samples in the interval [%]")
    ax_in.set_ylim(0, 105)
    ax_in.set_xticks(range(len(cases)))
    ax_in.set_xticklabels(labels, rotation=90, fontsize=7)
    fig.tight_layout()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"plot_nees: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
