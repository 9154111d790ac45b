"""Propeller-damage benchmark: randomized damaged and undamaged SITL flights with the
firmware's damage detector in the loop (docs/damage.md).

Damaged flights: a quad preset (plus or X), a trajectory, the Filter mode (the
controller allocates with the filter's estimates, so it re-allocates after a
detection), a loss of U(10 %, 50 %) of one rotor's kf and km at U(2, 3) s and, in
a third of the flights, a second rotor later. Each is flown again in Oracle mode
(the allocation knows the damage at once) for the tracking reference. Undamaged
flights: random mild effects on. Every flight uses the default (non-paper)
sensors: a 1 kHz BMI088-class gyro, DShot telemetry with quantisation, latency
and dropouts.
"""

from __future__ import annotations

import json
import math
import random
import subprocess
import sys
import tempfile
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from propid import table1
from propid.campaign import LIBRARY_RATE_PROCESS_NOISE, CampaignConfig, Job, sitl_command
from propid.errors import UserError
from propid.outputs import make_directory, save_figure, write_text

PRESETS = ("crazyflie-plus", "crazyflie-x")
# Effects the filter flies with (docs/sitl.md); esc_delay at its default 20 ms is
# left out: without delay compensation the filter itself diverges with it.
# Reading the tracking misses (fixed before they were counted): a damaged flight
# whose Filter/Oracle ratio exceeds 1.5 is attributed to
# - the Filter's gap before any damage when its undamaged twin's RMSE alone is at
#   least sqrt(1.5^2 - 1) = 1.118x the damaged Oracle's (independent errors add in
#   quadrature: that alone puts the ratio at 1.5 or above), and/or
# - a lost yaw when the Oracle itself, knowing the damage, keeps a yaw RMSE above
#   10 deg after it (a quad's yaw authority is its drag torque: a large loss uses
#   it up and the vehicle spins; the outcome is then chaotic in both modes).
MISS_GAP_FACTOR = math.sqrt(1.5 ** 2 - 1.0)
MISS_YAW_LOST_DEG = 10.0
# The undamaged twins' Filter/Oracle ratio divides errors that are often below a
# millimetre (an Oracle on the step or the circle tracks to 0.4-0.5 mm): 0.05 mm
# against 0.0006 mm reads 85x. The twins' rows therefore also give both RMSEs in mm,
# the ratio with each RMSE held at this floor (a position error below a millimetre
# is not the tracking the target reads: the damaged Oracles sit at 1-3 cm), and the
# twin Filter's RMSE over its damaged Oracle's, the share of the target's ratio the
# gap alone takes (MISS_GAP_FACTOR and above alone makes a miss).
TWIN_RMSE_FLOOR_M = 1e-3
# The DShot telemetry's latency [s] (propid_sitl's sensor default, set explicitly) and
# the filter holding it as its delay (docs/math.md §12): a datasheet figure the
# integrator knows, not fitted. Without it the filter reads speeds 1 ms late as
# current and its kf drift before any damage is the bench's largest tracking
# miss (docs/damage-history.md, "The filter holding the telemetry latency").
TELEMETRY_LATENCY_S = 0.001
# The filter's configuration matched to these sensors (docs/damage-history.md, "D read by the paired
# rule"): the library's rate process noise (propid_config_default), not the campaign's 4e-4
# chosen for the paper's exact-speed sensors, which makes the filter claim an opposite pair's
# common mode 9-79x too precisely under DShot quantisation ("The drift before the damage"); and
# the detector's derived design for the smallest loss the target asks detection for, whose
# floor and shift follow that filter's own R / S (docs/math.md §4).
FILTER_RATE_NOISE = LIBRARY_RATE_PROCESS_NOISE
DAMAGE_DESIGN_LOSS = 0.2
# The filter's accelerometer aiding (docs/math.md §9, the library's accelerometer tuning): every
# flight controller has an accelerometer, and its z specific force measures the collective thrust,
# the combination whose error the gyro leaves and the controller turns into a z offset
# (docs/damage.md, "E read by the paired rule"). BenchConfig.filter_accel = False flies without it.
FILTER_ACCEL = True
# The accelerometer z bias's prior standard deviation [m/s^2]: the IMU datasheet's zero-g offset
# (BMI088 class, +-20 mg typ., the figure propid_sitl's sensor draws its bias within), in place of
# the library's 0.5 m/s^2. At a steady hover the accelerometer sees the collective thrust and its
# bias only as a sum, and the priors' ratio splits it (docs/damage.md, "F read by the paired rule").
# BenchConfig.accel_bias_std = None flies the library's prior.
ACCEL_BIAS_STD = 20e-3 * 9.80665
MILD_EFFECTS = ("rotor_inertia", "rotor_gyroscopic", "rotor_drag", "translational_lift",
                "thrust_nonlinearity", "aero_damping", "gyro_scale", "com_offset")


@dataclass
class BenchConfig:
    sitl: Path
    out_dir: Path
    damaged: int = 200
    undamaged: int = 100
    duration_s: float = 6.0
    base_seed: int = 1000
    workers: int = 2
    false_alarms_per_hour: float | None = None  # detector design rate (None: library default)
    filter_accel: bool = FILTER_ACCEL  # the filter fuses the accelerometer (--filter-accel)
    accel_bias_std: float | None = ACCEL_BIAS_STD  # with filter_accel (--prior-accel-bias-std; None: library)
    # each damaged flight's Oracle also flown told this late (--oracle-damage-delay; None: not flown)
    late_oracle_s: float | None = None
    # extra propid_sitl options for every flight (e.g. a filter option), recorded in the conditions
    sitl_args: list[str] = field(default_factory=list)


@dataclass
class FlightSpec:
    index: int
    seed: int
    preset: str
    trajectory: str
    damages: list[tuple[int, float, float]] = field(default_factory=list)  # (rotor 1-based, t, fraction)
    effects: list[str] = field(default_factory=list)


def flight_specs(config: BenchConfig) -> list[FlightSpec]:
    """The randomized flight list (deterministic for a base seed)."""
    rng = random.Random(config.base_seed)
    specs = []
    for k in range(config.damaged + config.undamaged):
        seed = config.base_seed + k
        spec = FlightSpec(index=k, seed=seed, preset=rng.choice(PRESETS),
                          trajectory=table1.TRAJECTORIES[k % len(table1.TRAJECTORIES)])
        if k < config.damaged:
            rotor = rng.randint(1, 4)
            first = rng.uniform(2.0, 3.0)
            spec.damages.append((rotor, round(first, 3), round(rng.uniform(0.1, 0.5), 3)))
            if k % 3 == 2:  # a second rotor later
                other = rng.choice([r for r in range(1, 5) if r != rotor])
                spec.damages.append((other, round(first + rng.uniform(2.0, 2.5), 3),
                                     round(rng.uniform(0.1, 0.5), 3)))
        else:
            count = rng.randint(1, 3)
            spec.effects = sorted(rng.sample(MILD_EFFECTS, count))
        specs.append(spec)
    return specs


def _command(config: BenchConfig, spec: FlightSpec, mode: str, log: Path, summary: Path) -> list[str]:
    campaign = CampaignConfig(out_dir=config.out_dir, sitl=config.sitl, duration_s=config.duration_s,
                              vehicle=spec.preset, paper_sensors=False, filter_rate_noise=FILTER_RATE_NOISE)
    cmd = sitl_command(campaign, Job(spec.trajectory, mode, spec.index, spec.seed), log)
    cmd += ["--detect-damage", "--summary-json", str(summary),
            "--esc-latency", repr(TELEMETRY_LATENCY_S), "--filter-esc-delay", repr(TELEMETRY_LATENCY_S),
            "--damage-design-loss", repr(DAMAGE_DESIGN_LOSS)]
    if config.filter_accel:
        cmd += ["--filter-accel"]
        if config.accel_bias_std:
            cmd += ["--prior-accel-bias-std", repr(config.accel_bias_std)]
    if config.false_alarms_per_hour:
        cmd += ["--damage-false-alarm-rate", repr(config.false_alarms_per_hour)]
    for rotor, time_s, fraction in spec.damages:
        cmd += ["--damage", f"{rotor}@{time_s}={fraction}"]
    for effect in spec.effects:
        cmd += ["--effect", effect]
    return cmd + list(config.sitl_args)


def _fly(config: BenchConfig, spec: FlightSpec, mode: str, work: Path,
         after_s: float | None = None) -> dict:
    """One flight; the position RMSE from after_s (default: the first damage) to the end."""
    log = work / f"f{spec.index}_{mode}.csv"
    summary = work / f"f{spec.index}_{mode}.json"
    cmd = _command(config, spec, mode, log, summary)
    if after_s is None and spec.damages:
        after_s = spec.damages[0][1]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, check=False)
    out: dict = {"exit_code": proc.returncode}
    try:
        if proc.returncode not in (0, 3) or not summary.is_file():
            out["error"] = (proc.stderr or "").strip().splitlines()[-1:] or ["no summary"]
            return out
        data = json.loads(summary.read_text())
        out["stable"] = bool(data.get("stable")) and proc.returncode == 0
        out["diverged_at_s"] = data.get("diverged_at_s")
        out["touchdown_at_s"] = data.get("touchdown_at_s")
        out["detections"] = data.get("detections", [])
        out["on_ground"] = [bool(d.get("on_ground")) for d in data.get("damage", [])]
        out["after_touchdown"] = [bool(d.get("after_touchdown")) for d in data.get("damage", [])]
        if data.get("accel") is not None:  # the filter's accelerometer aiding (--filter-accel)
            out["accel"] = data["accel"]
        if after_s is not None and log.is_file():
            columns = table1.read_log_columns(log)
            after = columns["t"] >= after_s
            err = np.sqrt(sum((columns[f"p{a}"] - columns[f"ref_p{a}"]) ** 2 for a in "xyz"))
            out["rmse_after_damage_m"] = float(np.sqrt(np.mean(err[after] ** 2))) if np.any(after) else None
            yaw = table1.yaw_from_quaternion(columns["qw"], columns["qx"], columns["qy"], columns["qz"])
            yaw_err = table1.wrap_angle(yaw - columns["ref_yaw"])
            out["rmse_yaw_after_damage_deg"] = (math.degrees(float(np.sqrt(np.mean(yaw_err[after] ** 2))))
                                                if np.any(after) else None)
            if mode == "filter" and np.any(after):
                out["coefficients_at_damage"] = coefficients_at(columns, int(np.argmax(after)))
    finally:
        for path in (log, log.with_suffix(".vehicle.json"), summary):
            path.unlink(missing_ok=True)
    return out


def coefficients_at(columns: dict, k: int) -> dict | None:
    """The filter's kf and km at log row k over the truth, minus 1, and its claimed standard
    deviations over the truth, per rotor; None when the log carries no estimate."""
    count = table1.rotor_count(columns)
    if count == 0 or f"est_kf_{count}" not in columns:
        return None
    out = {}
    for name in ("kf", "km"):
        truth = np.array([columns[f"true_{name}_{i}"][k] for i in range(1, count + 1)])
        out[f"{name}_error"] = [float(x) for x in np.array(
            [columns[f"est_{name}_{i}"][k] for i in range(1, count + 1)]) / truth - 1.0]
        out[f"{name}_std"] = [float(x) for x in np.array(
            [columns[f"std_{name}_{i}"][k] for i in range(1, count + 1)]) / truth]
    return out


def opposite_pair_drift(coefficients: dict | None) -> tuple[float, float] | None:
    """The combination that drifts before a damage (docs/damage.md, "The drift before the
    damage"): the common mode of an opposite pair's kf (rotors i and i + N/2), which the gyro sees
    only through the pair's differential speed. Returns the pair's mean relative error with the
    largest magnitude and that error over the pair's mean claimed standard deviation."""
    if not coefficients:
        return None
    error, std = np.array(coefficients["kf_error"]), np.array(coefficients["kf_std"])
    half = len(error) // 2
    if half == 0 or len(error) % 2:
        return None
    common = 0.5 * (error[:half] + error[half:])
    spread = 0.5 * (std[:half] + std[half:])
    worst = int(np.argmax(np.abs(common)))
    return float(common[worst]), float(abs(common[worst]) / max(spread[worst], 1e-12))


def run_flight(config: BenchConfig, spec: FlightSpec) -> dict:
    """One spec: the Filter flight, and for a damaged one its Oracle twin."""
    with tempfile.TemporaryDirectory(prefix="propid_damage_") as tmp:
        work = Path(tmp)
        record = {"spec": asdict(spec), "filter": _fly(config, spec, "filter", work)}
        if spec.damages:
            record["oracle"] = _fly(config, spec, "oracle", work)
            if config.late_oracle_s:
                late = replace(config, sitl_args=list(config.sitl_args)
                               + ["--oracle-damage-delay", repr(config.late_oracle_s)])
                record["oracle_late"] = _fly(late, spec, "oracle", work)
            # The same flights without the damage, over the same window: how much of
            # the Filter/Oracle gap is there before any damage.
            intact = replace(spec, damages=[])
            record["filter_undamaged"] = _fly(config, intact, "filter", work, spec.damages[0][1])
            record["oracle_undamaged"] = _fly(config, intact, "oracle", work, spec.damages[0][1])
    return record


def score_damages(spec: dict, flight: dict) -> list[dict]:
    """Per damage: detected?, delay, isolated rotor, isolation delay."""
    detections = flight.get("detections", [])
    damages = spec["damages"]
    on_ground = flight.get("on_ground", [])
    after_touchdown = flight.get("after_touchdown", [])
    out = []
    for k, (rotor, time_s, fraction) in enumerate(damages):
        end = damages[k + 1][1] if k + 1 < len(damages) else math.inf
        window = [d for d in detections if time_s <= d["time_s"] < end]
        first = window[0] if window else None
        right = next((d for d in window if d["rotor"] == rotor), None)
        resting = bool(on_ground[k]) if k < len(on_ground) else False
        crashed = bool(after_touchdown[k]) if k < len(after_touchdown) else False
        out.append({
            "rotor": rotor, "time_s": time_s, "fraction": fraction,
            # struck a vehicle already down on the ground: resting on it at that
            # instant, or touched it again after flying (a crashed vehicle whose
            # rotors lift it off by millimetres reads airborne for a sample). The
            # contact holds the attitude, no gyro-based test can see it (counted apart).
            "on_ground": resting or crashed,
            "resting": resting,
            "after_touchdown": crashed,
            "detected": first is not None,
            "detect_ms": (first["time_s"] - time_s) * 1e3 if first else None,
            "isolated_rotor": first["rotor"] if first else None,
            "isolated_correctly": bool(first and first["rotor"] == rotor),
            "isolate_ms": (right["time_s"] - time_s) * 1e3 if right else None,
        })
    return out


def lost(flight: dict) -> bool:
    """The flight was lost: diverged (the SITL's flag) or crashed (touched the ground again
    after flying), whichever first. A crash is a loss whatever the wreck does afterwards."""
    return not flight.get("stable", False) or flight.get("touchdown_at_s") is not None


def within_crash_aware(filter_lost: bool, oracle_lost: bool, ratio: float | None) -> bool:
    """Tracking within 1.5x of the Oracle with a crash counted as a crash: both lost is a tie,
    the Filter lost alone a miss, the Oracle lost alone within; otherwise the RMSE ratio."""
    if filter_lost or oracle_lost:
        return oracle_lost
    return ratio is not None and ratio <= 1.5


def _miss_causes(record: dict, oracle_rmse: float) -> tuple[bool, bool]:
    """(the Filter's gap before the damage explains it, the Oracle lost yaw) for a flight above 1.5x."""
    intact = record.get("filter_undamaged", {}).get("rmse_after_damage_m")
    gap = intact is not None and intact >= MISS_GAP_FACTOR * oracle_rmse
    yaw = record.get("oracle", {}).get("rmse_yaw_after_damage_deg")
    return gap, yaw is not None and yaw > MISS_YAW_LOST_DEG


def twin_rows(twins: list[tuple[float, float, float]]) -> dict:
    """The undamaged twins of one trajectory, read in absolute terms: (Filter twin RMSE, Oracle
    twin RMSE, damaged Oracle RMSE) per flight -> the medians in mm, the median ratio with both
    RMSEs held at TWIN_RMSE_FLOOR_M, and the median twin Filter RMSE over the damaged Oracle's."""
    if not twins:
        return {"undamaged_filter_rmse_median_mm": None, "undamaged_oracle_rmse_median_mm": None,
                "undamaged_ratio_floored_median": None, "undamaged_over_damaged_oracle_median": None}
    values = np.array(twins, dtype=float)
    floored = np.maximum(values[:, 0], TWIN_RMSE_FLOOR_M) / np.maximum(values[:, 1], TWIN_RMSE_FLOOR_M)
    return {"undamaged_filter_rmse_median_mm": float(1e3 * np.median(values[:, 0])),
            "undamaged_oracle_rmse_median_mm": float(1e3 * np.median(values[:, 1])),
            "undamaged_ratio_floored_median": float(np.median(floored)),
            "undamaged_over_damaged_oracle_median": float(np.median(values[:, 0] / values[:, 2]))}


def accel_bias_rows(records: list[dict]) -> dict | None:
    """With the filter's accelerometer aiding: its z bias state at the end of the flight against
    the sensor's bias, per group of Filter flights not lost (damaged; their undamaged twins;
    the undamaged flights with effects). A collective thrust loss the bias absorbed would make the
    damaged flights' error stand out from their twins'. None without the aiding."""
    groups = {"damaged": [r["filter"] for r in records if r["spec"]["damages"]],
              "undamaged_twins": [r["filter_undamaged"] for r in records if "filter_undamaged" in r],
              "undamaged_with_effects": [r["filter"] for r in records if not r["spec"]["damages"]]}
    if not any("accel" in f for flights in groups.values() for f in flights):
        return None
    out = {}
    for name, flights in groups.items():
        rows = [f["accel"] for f in flights if "accel" in f and not lost(f)]
        error = np.array([row["est_bias_z"] - row["true_bias_z"] for row in rows], dtype=float)
        std = np.array([row["est_bias_std_z"] for row in rows], dtype=float)
        out[name] = {
            "flights": len(rows),
            "abs_error_median_m_s2": float(np.median(np.abs(error))) if len(rows) else None,
            "abs_error_p95_m_s2": float(np.percentile(np.abs(error), 95)) if len(rows) else None,
            "error_over_std_median": (float(np.median(np.abs(error) / np.maximum(std, 1e-12)))
                                      if len(rows) else None),
            "gated_samples": int(sum(row["gated"] for row in rows)),
            "reanchored_flights": sum(1 for row in rows if row["reanchored"] > 0)}
    return out


def late_oracle_rows(damaged: list[dict], delay_s: float | None) -> dict | None:
    """The Oracle told delay_s late against the Oracle told at once (crash-aware, as the Filter is
    read): how much of the target's 1.5x a detector that takes delay_s uses up by itself, over
    every damaged flight and split by whether the Oracle holds yaw (its yaw RMSE after the damage
    at most MISS_YAW_LOST_DEG); and the Filter against that late Oracle. None when not flown."""
    rows = [r for r in damaged if "oracle_late" in r and "oracle" in r]
    if not delay_s or not rows:
        return None

    def within(a: dict, b: dict) -> bool:
        ratio = None
        if a.get("rmse_after_damage_m") is not None and b.get("rmse_after_damage_m"):
            ratio = a["rmse_after_damage_m"] / b["rmse_after_damage_m"]
        return within_crash_aware(lost(a), lost(b), ratio)

    def share(flags: list[bool]) -> float | None:
        return sum(flags) / len(flags) if flags else None

    def spins(r: dict) -> bool:
        yaw = r["oracle"].get("rmse_yaw_after_damage_deg")
        return yaw is not None and yaw > MISS_YAW_LOST_DEG
    late_vs_oracle = [(within(r["oracle_late"], r["oracle"]), spins(r)) for r in rows]
    return {"delay_s": delay_s, "flights": len(rows),
            "late_within_1_5x_of_oracle": share([w for w, _ in late_vs_oracle]),
            "late_within_1_5x_of_oracle_holds_yaw": share([w for w, s in late_vs_oracle if not s]),
            "late_within_1_5x_of_oracle_spins": share([w for w, s in late_vs_oracle if s]),
            "oracle_spins_flights": sum(1 for _, s in late_vs_oracle if s),
            "late_lost": sum(1 for r in rows if lost(r["oracle_late"])),
            "filter_within_1_5x_of_late_oracle": share([within(r["filter"], r["oracle_late"]) for r in rows])}


def summarise(records: list[dict], config: BenchConfig) -> dict:
    damaged = [r for r in records if r["spec"]["damages"]]
    undamaged = [r for r in records if not r["spec"]["damages"]]
    events = []
    spurious = 0
    ratios, filt_rmse, orac_rmse = [], [], []
    misses: list[tuple[bool, bool]] = []
    yaw_held: list[float] = []  # the ratios of the flights whose Oracle holds yaw
    per_trajectory: dict[str, dict[str, list[float]]] = {}
    drift_cells: dict[str, list[tuple[float, float, float, float]]] = {}
    crash_aware: list[bool] = []       # every damaged flight, crash-aware tracking
    oracle_not_lost: list[bool] = []   # the flights whose Oracle is not lost
    lost_pairs: list[tuple[bool, bool]] = []
    for record in damaged:
        flight = record["filter"]
        f_lost, o_lost = lost(flight), lost(record.get("oracle", {}))
        lost_pairs.append((f_lost, o_lost))
        ratio = None
        if flight.get("rmse_after_damage_m") is not None and record.get("oracle", {}).get("rmse_after_damage_m"):
            ratio = flight["rmse_after_damage_m"] / record["oracle"]["rmse_after_damage_m"]
        crash_aware.append(within_crash_aware(f_lost, o_lost, ratio))
        if not o_lost:
            oracle_not_lost.append(crash_aware[-1])
        record["damages_scored"] = score_damages(record["spec"], flight)
        events += record["damages_scored"]
        first_damage = record["spec"]["damages"][0][1]
        spurious += sum(1 for d in flight.get("detections", []) if d["time_s"] < first_damage)
        f_rmse = flight.get("rmse_after_damage_m")
        o_rmse = record.get("oracle", {}).get("rmse_after_damage_m")
        if f_rmse is not None and o_rmse:
            ratios.append(f_rmse / o_rmse)
            if f_rmse / o_rmse > 1.5:
                misses.append(_miss_causes(record, o_rmse))
            oracle_yaw = record.get("oracle", {}).get("rmse_yaw_after_damage_deg")
            if oracle_yaw is None or oracle_yaw <= MISS_YAW_LOST_DEG:
                yaw_held.append(f_rmse / o_rmse)
            filt_rmse.append(f_rmse)
            orac_rmse.append(o_rmse)
            cell = per_trajectory.setdefault(record["spec"].get("trajectory", "?"),
                                             {"damaged": [], "undamaged": [], "twins": []})
            cell["damaged"].append(f_rmse / o_rmse)
            f_intact = record.get("filter_undamaged", {}).get("rmse_after_damage_m")
            o_intact = record.get("oracle_undamaged", {}).get("rmse_after_damage_m")
            if f_intact is not None and o_intact:
                cell["undamaged"].append(f_intact / o_intact)
                cell["twins"].append((f_intact, o_intact, o_rmse))
            drift = opposite_pair_drift(record.get("filter_undamaged", {}).get("coefficients_at_damage"))
            if drift is not None and f_intact is not None and o_intact:
                # per trajectory and preset: the drift is a pair of one geometry on one trajectory
                key = f"{record['spec'].get('trajectory', '?')}/{record['spec'].get('preset', '?')}"
                drift_cells.setdefault(key, []).append((f_intact, o_intact) + drift)
    airborne = [e for e in events if not e["on_ground"]]
    detected = [e for e in airborne if e["detected"]]
    big = [e for e in airborne if e["fraction"] >= 0.2]
    detect_ms = np.array([e["detect_ms"] for e in detected], dtype=float)
    isolate_ms = np.array([e["isolate_ms"] for e in airborne if e["isolate_ms"] is not None], dtype=float)

    def pct(values, q):
        return float(np.percentile(values, q)) if len(values) else None
    false_alarms = sum(len(r["filter"].get("detections", [])) for r in undamaged)
    stable = [r["filter"].get("stable", False) for r in records]
    return {
        "flights": len(records),
        "damaged_flights": len(damaged),
        "undamaged_flights": len(undamaged),
        "oracle_flights": sum(1 for r in damaged if "oracle" in r),
        "damage_events": len(events),
        "damage_events_on_ground": len(events) - len(airborne),
        # of those, the ones the contact flag alone read as airborne (down after a crash)
        "damage_events_after_touchdown_only": sum(1 for e in events
                                                  if e["after_touchdown"] and not e["resting"]),
        "detected_on_ground": sum(1 for e in events if e["on_ground"] and e["detected"]),
        "detection_rate": len(detected) / len(airborne) if airborne else None,
        "detection_rate_all_events": (sum(1 for e in events if e["detected"]) / len(events)
                                      if events else None),
        "detection_rate_ge20": (sum(1 for e in big if e["detected"]) / len(big)) if big else None,
        "median_detect_ms": pct(detect_ms, 50),
        "p95_detect_ms": pct(detect_ms, 95),
        "median_isolate_ms": pct(isolate_ms, 50),
        "p95_isolate_ms": pct(isolate_ms, 95),
        "isolation_accuracy": (sum(1 for e in detected if e["isolated_correctly"]) / len(detected)
                               if detected else None),
        "false_alarms": false_alarms,
        "false_alarm_flights": sum(1 for r in undamaged if r["filter"].get("detections")),
        "detections_before_damage": spurious,
        "tracking_rmse_after_damage_filter_m": float(np.mean(filt_rmse)) if filt_rmse else None,
        "tracking_rmse_after_damage_oracle_m": float(np.mean(orac_rmse)) if orac_rmse else None,
        "tracking_ratio_median": pct(ratios, 50),
        "tracking_ratio_p95": pct(ratios, 95),
        "tracking_within_1_5x": (sum(1 for x in ratios if x <= 1.5) / len(ratios)) if ratios else None,
        # The same share over the flights whose Oracle holds yaw (docs/damage.md): where it
        # spins, the ratio compares two uncontrolled flights. The target stays the share above.
        "tracking_within_1_5x_oracle_holds_yaw": (sum(1 for x in yaw_held if x <= 1.5) / len(yaw_held)
                                                  if yaw_held else None),
        "oracle_holds_yaw_flights": len(yaw_held),
        "tracking_per_trajectory": {
            traj: {"ratio_median": pct(cell["damaged"], 50),
                   "within_1_5x": sum(1 for x in cell["damaged"] if x <= 1.5) / len(cell["damaged"]),
                   "undamaged_ratio_median": pct(cell["undamaged"], 50),
                   "undamaged_within_1_5x": (sum(1 for x in cell["undamaged"] if x <= 1.5) / len(cell["undamaged"])
                                             if cell["undamaged"] else None),
                   **twin_rows(cell["twins"]),
                   "flights": len(cell["damaged"])}
            for traj, cell in sorted(per_trajectory.items())},
        # The undamaged twins' drift at the damage time, per trajectory and preset (docs/damage.md,
        # "The drift before the damage"): the opposite pair whose kf common mode is furthest off.
        "twin_drift": {
            key: {"flights": len(rows),
                  "filter_rmse_median_mm": float(1e3 * np.median([r[0] for r in rows])),
                  "oracle_rmse_median_mm": float(1e3 * np.median([r[1] for r in rows])),
                  "pair_kf_error_median": float(np.median([r[2] for r in rows])),
                  "pair_kf_abs_error_median": float(np.median([abs(r[2]) for r in rows])),
                  "pair_kf_error_over_std_median": float(np.median([r[3] for r in rows]))}
            for key, rows in sorted(drift_cells.items())},
        "tracking_misses": {
            "flights": len(misses),
            "filter_gap_before_damage": sum(1 for gap, _ in misses if gap),
            "oracle_yaw_lost": sum(1 for _, yaw in misses if yaw),
            "both": sum(1 for gap, yaw in misses if gap and yaw),
            "neither": sum(1 for gap, yaw in misses if not gap and not yaw)},
        # Crash-aware (docs/damage.md, Metrics): a flight is lost when it diverged or touched the
        # ground again after flying; both lost is a tie, the Filter lost alone a miss.
        "tracking_within_1_5x_crash_aware": (sum(crash_aware) / len(crash_aware)) if crash_aware else None,
        "tracking_within_1_5x_oracle_not_lost": (sum(oracle_not_lost) / len(oracle_not_lost)
                                                 if oracle_not_lost else None),
        "oracle_not_lost_flights": len(oracle_not_lost),
        "lost_flights": {
            "filter": sum(1 for f, _ in lost_pairs if f),
            "oracle": sum(1 for _, o in lost_pairs if o),
            "both": sum(1 for f, o in lost_pairs if f and o),
            "filter_only": sum(1 for f, o in lost_pairs if f and not o),
            "oracle_only": sum(1 for f, o in lost_pairs if o and not f),
            "filter_undamaged": sum(1 for r in undamaged if lost(r["filter"]))},
        # detections on a vehicle already down after flying (a wreck whose rotors still run;
        # docs/damage.md, "Ground contact"), Filter flights, damaged and undamaged
        "detections_after_touchdown": sum(
            1 for r in records for d in r["filter"].get("detections", [])
            if r["filter"].get("touchdown_at_s") is not None and d["time_s"] >= r["filter"]["touchdown_at_s"]),
        "stable_no_crash_pct": (100.0 * sum(not lost(r["filter"]) for r in records) / len(records)
                                if records else None),
        "oracle_stable_no_crash_pct": (100.0 * sum(not lost(r["oracle"]) for r in damaged if "oracle" in r)
                                       / len(damaged)) if damaged else None,
        "stable_pct": 100.0 * sum(stable) / len(stable) if stable else None,
        "oracle_stable_pct": (100.0 * sum(r["oracle"].get("stable", False) for r in damaged if "oracle" in r)
                              / len(damaged)) if damaged else None,
        "accel_bias": accel_bias_rows(records),
        "late_oracle": late_oracle_rows(damaged, config.late_oracle_s),
        "errors": [r["filter"]["error"] for r in records if "error" in r["filter"]][:5],
        "conditions": {"duration_s": config.duration_s, "base_seed": config.base_seed,
                       "presets": list(PRESETS), "trajectories": list(table1.TRAJECTORIES),
                       "loss_range": [0.1, 0.5], "first_damage_s": [2.0, 3.0],
                       "second_damage_after_s": [2.0, 2.5], "mild_effects": list(MILD_EFFECTS),
                       "sensors": "propid_sitl defaults (BMI088 1 kHz, DShot telemetry)",
                       "telemetry_latency_s": TELEMETRY_LATENCY_S,
                       "filter_delay_s": TELEMETRY_LATENCY_S,
                       "filter_rate_noise": FILTER_RATE_NOISE,
                       "damage_design_loss": DAMAGE_DESIGN_LOSS,
                       "filter_accel": config.filter_accel,
                       "accel_bias_std": config.accel_bias_std if config.filter_accel else None,
                       "late_oracle_s": config.late_oracle_s,
                       "false_alarms_per_hour": config.false_alarms_per_hour or 1e-3,
                       "sitl_args": list(config.sitl_args)},
        "per_flight": records,
    }


def run_bench(config: BenchConfig, progress: bool = True) -> dict:
    from tqdm import tqdm

    if not config.sitl.is_file():
        raise UserError(f"{config.sitl}: propid_sitl not found (make host)")
    make_directory(config.out_dir)
    specs = flight_specs(config)
    records = []
    bar = tqdm(total=len(specs), desc="damage-bench", unit="flight", disable=not progress,
               mininterval=0.5, file=sys.stderr)
    pool = ProcessPoolExecutor(max_workers=max(1, config.workers))
    try:
        pending = {pool.submit(run_flight, config, spec) for spec in specs}
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                records.append(future.result())
                bar.update(1)
    except KeyboardInterrupt:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    finally:
        pool.shutdown(wait=True)
        bar.close()
    records.sort(key=lambda r: r["spec"]["index"])
    result = summarise(records, config)
    write_text(config.out_dir / "damage_bench.json", json.dumps(result, indent=1) + "\n")
    return result


def _misses_text(misses: dict | None) -> str:
    if not misses:
        return "—"
    return (f"{misses['flights']}: {misses['filter_gap_before_damage']} / {misses['oracle_yaw_lost']} / "
            f"{misses['both']} / {misses['neither']}")


def _pct(value: float | None, scale: float = 100.0, spec: str = ".0f") -> str:
    return "—" if value is None else format(scale * value, spec)


def _lost_text(lost_flights: dict | None) -> str:
    if not lost_flights:
        return "—"
    return (f"{lost_flights['filter']} / {lost_flights['oracle']} / {lost_flights['both']} / "
            f"{lost_flights['filter_only']} / {lost_flights['oracle_only']} ({lost_flights['filter_undamaged']})")


def render(result: dict) -> str:
    def fmt(value, spec=".3g"):
        return "—" if value is None else format(value, spec)
    rows = [
        ("flights (damaged + undamaged; + Oracle twins)",
         f"{result['flights']} ({result['damaged_flights']} + {result['undamaged_flights']}; "
         f"+ {result['oracle_flights']})", ""),
        ("damage events (of which on a vehicle already down on the ground: resting, or touched down after flying)",
         f"{result['damage_events']} ({result.get('damage_events_on_ground', 0)}: "
         f"{result.get('damage_events_on_ground', 0) - result.get('damage_events_after_touchdown_only', 0)} / "
         f"{result.get('damage_events_after_touchdown_only', 0)})", ""),
        ("detection rate, airborne events (all / loss >= 20 %)",
         f"{fmt(100 * result['detection_rate'], '.1f')} % / {fmt(100 * result['detection_rate_ge20'], '.1f')} %",
         ">= 99 % for >= 20 %"),
        ("median / p95 detection delay", f"{fmt(result['median_detect_ms'])} / {fmt(result['p95_detect_ms'])} ms",
         "median <= 50 ms"),
        ("median / p95 isolation delay", f"{fmt(result['median_isolate_ms'])} / {fmt(result['p95_isolate_ms'])} ms",
         "median <= 100 ms"),
        ("isolation accuracy", f"{fmt(100 * result['isolation_accuracy'], '.1f')} %", ""),
        ("false alarms (undamaged flights)", (f"{result['false_alarms']} in {result['false_alarm_flights']} of "
                                              f"{result['undamaged_flights']} flights"),
         "0"),
        ("detections before the damage", str(result["detections_before_damage"]), "0"),
        ("tracking RMSE after damage, Filter / Oracle",
         f"{fmt(result['tracking_rmse_after_damage_filter_m'])} / "
         f"{fmt(result['tracking_rmse_after_damage_oracle_m'])} m", ""),
        ("Filter/Oracle ratio median / p95 (within 1.5x)",
         f"{fmt(result['tracking_ratio_median'])} / {fmt(result['tracking_ratio_p95'])} "
         f"({fmt(100 * result['tracking_within_1_5x'], '.0f')} % of flights)", "<= 1.5x"),
        ("same, flights whose Oracle holds yaw (yaw RMSE <= 10 deg after the damage)",
         (f"{fmt(None if result.get('tracking_within_1_5x_oracle_holds_yaw') is None else 100 * result['tracking_within_1_5x_oracle_holds_yaw'], '.0f')} "
          f"% of {result.get('oracle_holds_yaw_flights', 0)} flights"), ""),
        ("flights above 1.5x: Filter's gap before the damage / Oracle lost yaw / both / neither",
         _misses_text(result.get("tracking_misses")), ""),
        ("stable (Filter / Oracle)", f"{fmt(result['stable_pct'], '.1f')} % / {fmt(result['oracle_stable_pct'], '.1f')} %",
         ""),
        ("crash-aware: within 1.5x (both lost a tie, the Filter lost alone a miss) / over the flights "
         "whose Oracle is not lost",
         (f"{_pct(result.get('tracking_within_1_5x_crash_aware'))} % / "
          f"{_pct(result.get('tracking_within_1_5x_oracle_not_lost'))} % of "
          f"{result.get('oracle_not_lost_flights', 0)} flights"), ""),
        ("crash-aware: stable = neither diverged nor down after flying (Filter, every flight / "
         "Oracle, the damaged twins)",
         f"{_pct(result.get('stable_no_crash_pct'), 1.0, '.1f')} % / "
         f"{_pct(result.get('oracle_stable_no_crash_pct'), 1.0, '.1f')} %", ""),
        ("damaged flights lost: Filter / Oracle / both / Filter alone / Oracle alone (undamaged Filter)",
         _lost_text(result.get("lost_flights")), ""),
        ("detections after a touch-down (on a vehicle already down)",
         str(result.get("detections_after_touchdown", 0)), ""),
    ]
    lines = ["| metric | measured | target |", "|---|---|---|"]
    lines += [f"| {a} | {b} | {c} |" for a, b, c in rows]
    lines += ["", "Filter/Oracle position RMSE from the first damage time, per trajectory: the damaged",
              "flights, and the same flights without the damage (the gap that is there anyway). The twins'",
              "plain ratio divides sub-millimetre errors; beside it their RMSEs in mm, the ratio with each",
              f"RMSE held at {1e3 * TWIN_RMSE_FLOOR_M:g} mm, and the twin Filter's RMSE over the damaged Oracle's "
              f"(>= {MISS_GAP_FACTOR:.3f} alone makes a miss):", "",
              "| trajectory | damaged: median (within 1.5x) | undamaged twins: median (within 1.5x) | "
              "twins: Filter / Oracle RMSE, mm | twins, floored ratio | twin Filter / damaged Oracle | flights |",
              "|---|---|---|---|---|---|---|"]
    for traj, cell in result.get("tracking_per_trajectory", {}).items():
        lines.append(f"| {traj} | {fmt(cell['ratio_median'])} ({fmt(100 * cell['within_1_5x'], '.0f')} %) | "
                     f"{fmt(cell['undamaged_ratio_median'])} "
                     f"({fmt(None if cell['undamaged_within_1_5x'] is None else 100 * cell['undamaged_within_1_5x'], '.0f')} %) | "
                     f"{fmt(cell.get('undamaged_filter_rmse_median_mm'))} / "
                     f"{fmt(cell.get('undamaged_oracle_rmse_median_mm'))} | "
                     f"{fmt(cell.get('undamaged_ratio_floored_median'))} | "
                     f"{fmt(cell.get('undamaged_over_damaged_oracle_median'))} | {cell['flights']} |")
    if result.get("twin_drift"):
        lines += ["", "The undamaged twins at the first damage time: the opposite pair (rotors i, i + N/2) whose",
                  "kf common mode is furthest off the truth, median over the flights:", "",
                  "| trajectory / preset | twins: Filter / Oracle RMSE, mm | pair kf common mode: error "
                  "(median of the magnitude) | error / claimed std | flights |", "|---|---|---|---|---|"]
        for key, cell in result["twin_drift"].items():
            lines.append(f"| {key} | {fmt(cell['filter_rmse_median_mm'])} / {fmt(cell['oracle_rmse_median_mm'])} | "
                         f"{_pct(cell['pair_kf_error_median'], 100.0, '+.1f')} % "
                         f"({_pct(cell['pair_kf_abs_error_median'], 100.0, '.1f')} %) | "
                         f"{fmt(cell['pair_kf_error_over_std_median'])} | {cell['flights']} |")
    if result.get("accel_bias"):
        lines += ["", "The filter's accelerometer z bias at the end of the flight against the sensor's "
                  "(Filter flights not lost):", "",
                  "| flights | count | abs error median (p95), m/s^2 | abs error / claimed std, median | "
                  "gated samples | flights re-anchored |", "|---|---|---|---|---|---|"]
        for name, cell in result["accel_bias"].items():
            lines.append(f"| {name.replace('_', ' ')} | {cell['flights']} | {fmt(cell['abs_error_median_m_s2'])} "
                         f"({fmt(cell['abs_error_p95_m_s2'])}) | {fmt(cell['error_over_std_median'])} | "
                         f"{cell['gated_samples']} | {cell['reanchored_flights']} |")
    late = result.get("late_oracle")
    if late:
        lines += ["", f"The Oracle told {1e3 * late['delay_s']:g} ms late (the allocation a detector that takes "
                  "that long could give at best) against the Oracle told at once, crash-aware:", "",
                  "| late Oracle within 1.5x of the Oracle: all / Oracle holds yaw / Oracle spins | "
                  "late Oracle lost | Filter within 1.5x of the late Oracle | flights |", "|---|---|---|---|",
                  f"| {_pct(late['late_within_1_5x_of_oracle'], 100.0, '.1f')} % / "
                  f"{_pct(late['late_within_1_5x_of_oracle_holds_yaw'], 100.0, '.1f')} % / "
                  f"{_pct(late['late_within_1_5x_of_oracle_spins'], 100.0, '.1f')} % of "
                  f"{late['oracle_spins_flights']} | {late['late_lost']} | "
                  f"{_pct(late['filter_within_1_5x_of_late_oracle'], 100.0, '.1f')} % | {late['flights']} |"]
    return "\n".join(lines) + "\n"


def render_png(result: dict, path: str | Path) -> None:
    """Detection delay against the loss, and Filter/Oracle tracking after the damage."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    events = [e for r in result["per_flight"] for e in r.get("damages_scored", [])]
    ok = [e for e in events if e["detected"] and e["isolated_correctly"]]
    wrong = [e for e in events if e["detected"] and not e["isolated_correctly"]]
    missed = [e for e in events if not e["detected"]]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    ax1.scatter([100 * e["fraction"] for e in ok], [e["detect_ms"] for e in ok], s=10,
                label=f"detected, right rotor ({len(ok)})")
    if wrong:
        ax1.scatter([100 * e["fraction"] for e in wrong], [e["detect_ms"] for e in wrong], s=14,
                    marker="x", color="tab:red", label=f"detected, wrong rotor ({len(wrong)})")
    if missed:
        ax1.scatter([100 * e["fraction"] for e in missed], [0.0] * len(missed), s=14, marker="v",
                    color="k", label=f"missed ({len(missed)})")
    ax1.axhline(50.0, color="gray", ls="--", lw=0.8, label="50 ms")
    ax1.set_xlabel("loss of kf and km [%]")
    ax1.set_ylabel("detection delay [ms]")
    ax1.set_title("Damage detection")
    ax1.legend(fontsize=8)
    pairs = [(r["filter"].get("rmse_after_damage_m"), r.get("oracle", {}).get("rmse_after_damage_m"))
             for r in result["per_flight"] if r["spec"]["damages"]]
    pairs = [(f, o) for f, o in pairs if f is not None and o]
    if pairs:
        oracle = [o for _, o in pairs]
        ax2.scatter(oracle, [f for f, _ in pairs], s=10)
        top = max(max(oracle), max(f for f, _ in pairs))
        ax2.plot([0, top], [0, top], color="gray", lw=0.8, label="equal")
        ax2.plot([0, top], [0, 1.5 * top], color="gray", lw=0.8, ls="--", label="1.5x")
        ax2.set_xscale("log")
        ax2.set_yscale("log")
    ax2.set_xlabel("Oracle position RMSE after the damage [m]")
    ax2.set_ylabel("Filter position RMSE after the damage [m]")
    ax2.set_title("Tracking after the damage")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    try:
        save_figure(fig, path, dpi=120)
    finally:
        plt.close(fig)
