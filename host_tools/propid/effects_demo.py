"""`propid effects-demo`: what each optional filter term removes, on SITL flights with the
effect it models (docs/math.md §13).

For each effect, SITL flights with the effect at its default strength, the filter's matching
term off and on, in Oracle mode (the controller flies on the true coefficients: the filter's
estimates do not feed back into the flight) and in Filter mode (the controller uses them),
seeds 1..N. The measure is the filter's final kf and km over the true ones per rotor: their
mean and the worst rotor |ratio - 1| over rotors and seeds. Fixed before any flight was flown:
crazyflie-plus, Lissajous, default sensors (BMI088 at 1 kHz, DShot telemetry at 500 Hz with
1 ms latency), 20 s, library-default filter settings; the telemetry delay the filter is told
is the simulator's total (its 1 ms latency + the effect's 20 ms).
"""

from __future__ import annotations

import json
import statistics
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

from propid.errors import UserError
from propid.outputs import write_text

ESC_LATENCY_S = 0.001  # propid_sitl's default --esc-latency
# (effect, its default strength, the filter options that model it, what the term is)
CASES = [
    ("none", None, [], "no effect (baseline)"),
    ("com_offset", 0.05, ["--filter-disturbance"], "disturbance-torque states"),
    ("rotor_drag", 1.0, ["--filter-disturbance"], "disturbance-torque states"),
    ("rotor_inertia", 1.0, ["--filter-rotor-inertia"], "rotor inertia in the model"),
    ("esc_delay", 0.02, ["--filter-esc-delay", f"{ESC_LATENCY_S + 0.02:g}"], "telemetry delay held"),
    ("aero_damping", 1.0, ["--filter-aero-damping"], "aerodynamic damping in the model"),
]
MODES = ("oracle", "filter")


@dataclass
class DemoConfig:
    sitl: Path
    out_dir: Path
    seeds: int = 3
    duration_s: float = 20.0
    cases: tuple[str, ...] = tuple(case[0] for case in CASES)


def fly(sitl: Path, effect: str, strength: float | None, options: list[str], mode: str, seed: int,
        duration_s: float, work: Path) -> dict:
    """One flight; its kf and km over the truth per rotor."""
    summary = work / f"{effect}_{mode}_{seed}_{len(options)}.json"
    cmd = [str(sitl), "--mode", mode, "--seed", str(seed), "--duration", f"{duration_s:g}", "--quiet",
           "--summary-json", str(summary), *options]
    if effect != "none":
        cmd += ["--effect", f"{effect}={strength:g}"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    if proc.returncode not in (0, 3) or not summary.is_file():
        raise UserError(f"propid_sitl failed ({proc.returncode}): {' '.join(cmd)}\n{proc.stderr.strip()[:400]}")
    s = json.loads(summary.read_text())
    return {
        "stable": bool(s["stable"]),
        "kf": [e / t for e, t in zip(s["est_kf"], s["true_kf"])],
        "km": [e / t for e, t in zip(s["est_km"], s["true_km"])],
    }


def cell(flights: list[dict]) -> dict:
    kf = [r for f in flights for r in f["kf"]]
    km = [r for f in flights for r in f["km"]]
    return {
        "flights": len(flights),
        "stable": sum(f["stable"] for f in flights),
        "kf_mean": statistics.fmean(kf), "kf_worst": max(abs(r - 1.0) for r in kf),
        "km_mean": statistics.fmean(km), "km_worst": max(abs(r - 1.0) for r in km),
    }


def run_demo(config: DemoConfig, progress: bool = True) -> dict:
    cases = [case for case in CASES if case[0] in config.cases]
    jobs = [(case, mode, on, seed) for case in cases for mode in MODES for on in (False, True)
            for seed in range(1, config.seeds + 1)]
    iterator = jobs
    if progress:
        from tqdm import tqdm

        iterator = tqdm(jobs, desc="effects-demo", unit="flight")
    flights: dict[tuple, list] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for (effect, strength, options, _), mode, on, seed in iterator:
            flights.setdefault((effect, mode, on), []).append(
                fly(config.sitl, effect, strength, options if on else [], mode, seed, config.duration_s, Path(tmp)))
    rows = []
    for effect, strength, options, term in cases:
        for mode in MODES:
            rows.append({"effect": effect, "strength": strength, "term": term, "options": options, "mode": mode,
                         "off": cell(flights[(effect, mode, False)]), "on": cell(flights[(effect, mode, True)])})
    result = {"definitions": __doc__.strip(), "seeds": config.seeds, "duration_s": config.duration_s, "rows": rows}
    write_text(config.out_dir / "effects_demo.json", json.dumps(result, indent=2) + "\n")
    return result


def render(result: dict) -> str:
    lines = [f"Filter kf and km over the truth, mean over rotors and seeds (worst rotor |ratio - 1|), "
             f"{result['seeds']} seeds x {result['duration_s']:g} s per cell; term off -> on",
             "",
             "| effect | filter term (options) | mode | kf off | kf on | km off | km on | stable off/on |",
             "|---|---|---|---|---|---|---|---|"]
    for row in result["rows"]:
        off, on = row["off"], row["on"]
        effect = row["effect"] + (f"={row['strength']:g}" if row["strength"] is not None else "")
        options = " ".join(row["options"]) or "-"
        lines.append(
            f"| {effect} | {row['term']} (`{options}`) | {row['mode']} "
            f"| {off['kf_mean']:.3f} ({100 * off['kf_worst']:.1f} %) | {on['kf_mean']:.3f} ({100 * on['kf_worst']:.1f} %) "
            f"| {off['km_mean']:.3f} ({100 * off['km_worst']:.1f} %) | {on['km_mean']:.3f} ({100 * on['km_worst']:.1f} %) "
            f"| {off['stable']}/{off['flights']}, {on['stable']}/{on['flights']} |")
    return "\n".join(lines) + "\n"
