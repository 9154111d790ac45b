#!/usr/bin/env python3
"""The NEES of a soak plan's clean flights with extra propid_sitl options
(docs/reliability.md, "The unbiased decode").

Draws the plan exactly as `make soak` does (tests/soak/soak.py: the seed's random
cases until 1.05 x the planned filter steps), keeps its clean (NEES) flights, and
flies each once in filter mode with soak.py's command (the matched tuning, the
input errors from the sensor model, the damage detector, the whole-P check) plus
the options given for its sensor set. Prints and writes (--out) the share of NEES
samples in their 95 % band per sensor set, pooled, with covariance repairs, full-P
checks not positive definite, converged claims and non-finite estimates, and the
per-flight figures. With no extra options the figures are `make soak`'s.
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

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import rate_noise_rule  # noqa: E402  (the soak's loader and the NEES figures of one flight)
from propid.outputs import write_text  # noqa: E402


def clean_cases(seed: int, steps: float) -> list[dict]:
    """The clean cases of the plan `make soak SOAK_SEED=seed` flies."""
    soak = rate_noise_rule.load_soak()
    rng = random.Random(seed)
    cases, planned = [], 0.0
    while planned < 1.05 * steps:
        case = soak.plan_case(rng, len(cases))
        cases.append(case)
        planned += 2.0 * soak.expected_steps(case)
    return [case for case in cases if case["clean"]]


def fly_case(job: tuple) -> dict:
    sitl, case, extra, rule, window_s = job
    soak = rate_noise_rule.load_soak()
    calibration = None
    if rate_noise_rule.rule_applies(rule, case):
        calibration = rate_noise_rule.calibrate(
            case, lambda flight, summary: soak.command(sitl, flight, "filter", summary) + extra, window_s)
        if "error" in calibration:
            return {"case": case, "extra": extra, "calibration": calibration, "result": calibration}
        case = {**case, "rate_noise": calibration["q_rate"]}
    with tempfile.TemporaryDirectory(prefix="nees-options-") as work:
        summary = os.path.join(work, "flight.json")
        command = soak.command(sitl, case, "filter", summary) + extra
        proc = subprocess.run(command, capture_output=True, text=True)
        return {"case": case, "extra": extra, "calibration": calibration,
                "result": rate_noise_rule.nees_figures(summary, proc)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    rate_noise_rule.add_plan_arguments(parser)
    parser.add_argument("--jobs", type=int, default=2, help="flights in parallel (default 2)")
    parser.add_argument("--sensors", choices=("all", "default", "paper"), default="all",
                        help="fly only the clean flights with this sensor set (default all)")
    parser.add_argument("--default-args", default="",
                        help="extra propid_sitl options for the default-sensor flights, one string "
                             "(e.g. \"--esc-decode middle\")")
    parser.add_argument("--paper-args", default="", help="extra propid_sitl options for the paper-sensor flights")
    parser.add_argument("--rate-rule", choices=rate_noise_rule.RATE_RULES, default="none",
                        help="rate process noise rule of the flights: none (the soak's matched tuning, default) or "
                             "previous-flight (exact-speed flights take the q_rate derived from a previous flight "
                             "of the same vehicle and mission: the case with another seed)")
    parser.add_argument("--rate-rule-window", type=float, default=rate_noise_rule.WINDOW_S,
                        help="with --rate-rule previous-flight: the derivation's window [s] (default 1)")
    parser.add_argument("--limit", type=int, default=0, help="fly only the first N selected flights (0: all)")
    parser.add_argument("--out", help="write the figures and the per-flight results here (JSON)")
    args = parser.parse_args(argv)
    rate_noise_rule.check_sitl_and_out(parser, args)
    if args.jobs < 1 or args.steps <= 0 or args.limit < 0 or not args.rate_rule_window > 0:
        parser.error("--jobs must be >= 1, --steps > 0, --limit >= 0 and --rate-rule-window > 0")
    extra = {"default": shlex.split(args.default_args), "paper": shlex.split(args.paper_args)}
    cases = [case for case in clean_cases(args.seed, args.steps)
             if args.sensors in ("all", case["sensors"])]
    if args.limit:
        cases = cases[:args.limit]
    try:
        from tqdm import tqdm
    except ImportError:  # the bar is a convenience
        tqdm = None
    jobs = [(args.sitl, case, extra[case["sensors"]], args.rate_rule, args.rate_rule_window) for case in cases]
    with ProcessPoolExecutor(args.jobs) as pool:
        iterator = pool.map(fly_case, jobs)
        if tqdm:
            iterator = tqdm(iterator, total=len(jobs), unit="flight", desc=f"plan {args.seed}", file=sys.stderr)
        results = list(iterator)
    out = {"plan_seed": args.seed, "default_args": args.default_args, "paper_args": args.paper_args,
           "rate_rule": args.rate_rule, "rate_rule_window_s": args.rate_rule_window,
           "figures": rate_noise_rule.pooled(results, "result"), "flights": results}
    if args.out:
        write_text(args.out, json.dumps(out, indent=1) + "\n")
    print(json.dumps({key: out[key] for key in ("plan_seed", "default_args", "paper_args", "rate_rule", "figures")},
                     indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
