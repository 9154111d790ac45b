"""Run the bench: fly the plan, run `propid gap` and the baseline on each flight, score.

Each flight is one job on a process pool (one job per core): fly it (blind files +
answer key), run the tool as a separate process exactly as a user would
(`propid gap --log F.csv --vehicle F.vehicle.json --json OUT.json --report DIR`),
run the baseline in-process, return both results. The main process scores them
against the answer keys and writes OUT/gap_bench.json.
"""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from propid.gapbench import baseline
from propid.gapbench.census import flight_census, summarize_census
from propid.gapbench.flights import FlightMaker, clear
from propid.gapbench.magnitudes import DETECTABILITY_MAX, DETECTION_LIMIT, EFFECT_RANGES
from propid.gapbench.plan import FlightSpec, make_plan
from propid.gapbench.scoring import score_flight, summarize
from propid.outputs import make_directory, write_text


# The bench already runs one flight per core; a multi-threaded BLAS on top of that spins
# its threads against the other workers (measured: 5x the wall time on a loaded machine).
SINGLE_THREADED_BLAS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def default_tool_command() -> list[str]:
    # The bench scores the diagnosis (verdict, effects, shrink), not the firmware
    # filter's before/after replay, which costs ~10 s per flight: --no-filter.
    return [sys.executable, "-m", "propid.cli", "gap", "--no-filter", "--quiet"]


@dataclass
class BenchConfig:
    out_dir: Path            # flights/, answers/, tool/, baseline/
    result_path: Path        # the scored bench (gap_bench.json)
    sitl: Path
    seed: int = 1
    singles_per_effect: int = 5
    pairs: int = 15
    nones: int = 15
    effects: tuple[str, ...] | None = None
    duration_s: float = 12.0
    workers: int = 2
    tool_command: list[str] | None = field(default_factory=default_tool_command)
    tool_timeout_s: float = 600.0
    time_budget_s: float | None = None  # stop starting flights after this [s]
    reports: bool = False  # ask the tool for its HTML report too (not scored; ~2 s per flight)
    flights_per_diagnosis: int = 1  # K flights of one vehicle per diagnosis (plan.further_flight)


def tool_available(command: list[str]) -> tuple[bool, str]:
    """Whether `COMMAND --help` runs (the gap sub-command exists)."""
    try:
        proc = subprocess.run(command + ["--help"], capture_output=True, text=True, timeout=120,
                              check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return False, str(exc)
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
        return False, tail[0]
    return True, ""


def _run_tool(config: BenchConfig, flight_id: str, csvs: list[Path], vehicle: Path) -> dict:
    out_dir = config.out_dir / "tool"
    out_dir.mkdir(parents=True, exist_ok=True)
    out_json = out_dir / f"{flight_id}.json"
    logs = [arg for csv in csvs for arg in ("--log", str(csv))]
    command = config.tool_command + logs + ["--vehicle", str(vehicle), "--json", str(out_json)]
    if config.reports:
        command += ["--report", str(out_dir / f"{flight_id}_report")]
    start = time.monotonic()
    env = dict(os.environ, TQDM_DISABLE="1", **SINGLE_THREADED_BLAS)
    try:
        proc = subprocess.run(command, capture_output=True, text=True, timeout=config.tool_timeout_s,
                              check=False, env=env)
    except subprocess.TimeoutExpired:
        return {"result": None, "error": f"timed out after {config.tool_timeout_s:g} s",
                "wall_s": config.tool_timeout_s}
    wall = time.monotonic() - start
    if proc.returncode != 0:
        tail = " | ".join((proc.stderr or "").strip().splitlines()[-2:])
        return {"result": None, "error": f"exit {proc.returncode}: {tail}", "wall_s": wall}
    try:
        result = json.loads(out_json.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        return {"result": None, "error": f"unreadable OUT.json: {exc}", "wall_s": wall}
    return {"result": result, "error": None, "wall_s": wall}


def run_flight(config: BenchConfig, spec: FlightSpec, with_tool: bool) -> dict:
    """Worker: one flight end to end."""
    start = time.monotonic()
    answer = FlightMaker(config.sitl, config.out_dir).make(spec)
    fly_s = time.monotonic() - start
    flights = config.out_dir / "flights"
    csvs = [flights / f"{spec.flight_id}.csv"] + \
        [flights / further["csv"] for further in answer.get("further_flights", [])]
    vehicle = flights / f"{spec.flight_id}.vehicle.json"
    start = time.monotonic()
    try:
        base = baseline.diagnose(csvs, vehicle)
        base_error = None
    except Exception as exc:  # noqa: BLE001 - a baseline failure is scored as a failure
        base, base_error = None, f"{type(exc).__name__}: {exc}"
    base_s = time.monotonic() - start
    (config.out_dir / "baseline").mkdir(parents=True, exist_ok=True)
    if base is not None:
        (config.out_dir / "baseline" / f"{spec.flight_id}.json").write_text(
            json.dumps(base, indent=1) + "\n", encoding="utf-8")
    tool = _run_tool(config, spec.flight_id, csvs, vehicle) if with_tool else None
    return {"answer": answer, "baseline": base, "baseline_error": base_error, "tool": tool,
            "fly_s": fly_s, "baseline_s": base_s}


def run_bench(config: BenchConfig, progress: bool = True) -> dict:
    start = time.monotonic()
    make_directory(config.out_dir)
    clear(config.out_dir)
    plan = make_plan(config.seed, config.singles_per_effect, config.pairs, config.nones,
                     config.duration_s, effects=config.effects,
                     flights_per_diagnosis=config.flights_per_diagnosis)
    with_tool, why = (False, "disabled") if config.tool_command is None else \
        tool_available(config.tool_command)
    outcomes: list[dict] = []
    errors: list[str] = []
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(plan), unit="flight", desc="gap-bench", dynamic_ncols=True)
    # Submitted in a seeded random order, so that the flights done when a time budget
    # runs out are a fair sample of every kind, effect, vehicle and rate.
    order = np.random.default_rng(config.seed + 1).permutation(len(plan))
    cancelled = 0
    with ProcessPoolExecutor(max_workers=max(1, config.workers)) as pool:
        futures = {pool.submit(run_flight, config, plan[i], with_tool): plan[i] for i in order}
        for future in as_completed(futures):
            if future.cancelled():
                continue
            spec = futures[future]
            try:
                outcomes.append(future.result())
            except Exception as exc:  # noqa: BLE001 - report and go on with the others
                errors.append(f"{spec.flight_id}: {exc}")
            if bar is not None:
                bar.update(1)
            if (config.time_budget_s is not None and not cancelled
                    and time.monotonic() - start > config.time_budget_s):
                cancelled = sum(f.cancel() for f in futures)
    if bar is not None:
        bar.close()
    outcomes.sort(key=lambda o: o["answer"]["flight_id"])
    tool_records = [score_flight(o["answer"], (o["tool"] or {}).get("result")) for o in outcomes] \
        if with_tool else []
    # why each headline miss and false effect happened, from the tool's OUT.json (census.py)
    for o, record in zip(outcomes, tool_records):
        record["census"] = flight_census(o["answer"], (o["tool"] or {}).get("result"), record)
    base_records = [score_flight(o["answer"], o["baseline"]) for o in outcomes]
    tool_walls = [o["tool"]["wall_s"] for o in outcomes if o.get("tool")]
    result = {
        "config": {
            "seed": config.seed, "duration_s": config.duration_s, "workers": config.workers,
            "singles_per_effect": config.singles_per_effect, "pairs": config.pairs,
            "nones": config.nones, "flights_per_diagnosis": config.flights_per_diagnosis,
            "tool_command": None if config.tool_command is None
            else " ".join(shlex.quote(c) for c in config.tool_command),
            "detection_limit": DETECTION_LIMIT, "detectability_max": DETECTABILITY_MAX,
            "strength_max": {k: r.strength_max for k, r in EFFECT_RANGES.items()},
        },
        "tool_available": with_tool,
        "tool_unavailable_reason": None if with_tool else why,
        "tool": summarize(tool_records) if with_tool else None,
        "census": summarize_census([r["census"] for r in tool_records], tool_records) if with_tool else None,
        "baseline": summarize(base_records),
        "flights": [
            {
                "flight_id": o["answer"]["flight_id"],
                "kind": o["answer"]["kind"],
                "truth": o["answer"]["effects"],
                "vehicle": o["answer"]["spec"]["vehicle"],
                "trajectory": o["answer"]["spec"]["trajectory"],
                "rates": o["answer"]["spec"]["rates"],
                "nuisances": o["answer"]["spec"]["nuisances"],
                "sitl_command": o["answer"]["sitl_command"],
                **({"further_flights": o["answer"]["further_flights"]}
                   if "further_flights" in o["answer"] else {}),
                "tool": tool_records[i] if with_tool else None,
                "tool_error": (o["tool"] or {}).get("error") if with_tool else None,
                "baseline": base_records[i],
                "baseline_error": o["baseline_error"],
            }
            for i, o in enumerate(outcomes)
        ],
        "planned_flights": len(plan),
        "cancelled_flights": cancelled,
        "errors": errors,
        "runtime_s": {
            "total": time.monotonic() - start,
            "tool_per_flight_median": sorted(tool_walls)[len(tool_walls) // 2] if tool_walls else None,
        },
    }
    write_text(config.result_path, json.dumps(result, indent=1) + "\n")
    return result
