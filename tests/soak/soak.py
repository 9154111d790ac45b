#!/usr/bin/env python3
"""`make soak`: long randomized SITL flights with the filter in the loop.

Not a test with a pass/fail verdict on its own: a measurement of how the filter
behaves over many filter steps of varied flight (docs/reliability.md, "Soak").
A seeded plan of flights (vehicle, trajectory, duration, sensors, filter tuning,
0-2 unmodelled effects, 0-4 fault classes with random rates, a rotor losing
part of its kf and km mid-flight) is flown twice per case: with the filter's
estimates in the controller (mode filter) and with the true coefficients
(mode oracle; the filter runs there too). Flights run in parallel over --jobs
processes until the filter steps (accepted gyro samples, both modes) reach
--steps. Writes the figures to --out (JSON) and prints them.

Figures:
- steps: accepted gyro samples over all flights (both modes);
- faults_injected: per fault class, summed;
- nan_count: control steps with a non-finite estimate or std (must be 0);
- max_recovery_s: longest time, after a rotor lost part of its kf/km, until
  every kf and km was back within 10 % of the truth and stayed; `unrecovered`
  counts losses not recovered by the end of the flight. Split by what can be
  asked: `losses_from_accurate` / `recovered_from_accurate`: losses where every
  coefficient was within 10 % just before, and how many of them recovered;
  `lost_rotor_recovered` / `max_lost_rotor_recovery_s`: losses whose own
  rotor's kf and km came back within 10 % and stayed (other rotors may be off
  through an effect); `lost_rotor_from_accurate` / `lost_rotor_recovered_from_accurate`:
  losses whose rotor's kf and km were within 10 % just before, and how many of
  them came back (a return within 10 % is asked only of a filter that was
  there before the loss);
- nees_in_bounds_pct: over fault-free, effect-free flights without a rotor loss
  (mode filter), the share of control steps whose NEES of coefficients and gyro
  biases (full covariance block) lies inside its 95 % chi-square interval; also
  per tuning and sensor set, and per flight (nees_flights), with the shares
  below the interval (underconfident: the sigma too large, the safe side) and
  above it (overconfident): nees_below_bounds_pct / nees_above_bounds_pct. These flights use
  the "matched" tuning (--nees-tuning): the filter's priors and random walks
  are the distribution the simulator draws the truth from, without which a
  NEES is not chi-square distributed; --nees-rate-rule previous-flight gives
  the exact-speed NEES flights the rate process noise derived from a previous
  flight of the same vehicle and mission (tests/soak/rate_noise_rule.py) and
  --nees-default-rate-noise Q the default-sensor ones Q (both off by default);
- false_converged: coefficient "converged" claims (per coefficient and control
  step) while more than 5 % off, over all mode-filter flights; with the claims.
  No test on gyro and rotor speeds sees a scale error of the inertia J (the
  inertia_error effect), only the configuration can tell the claim about it.
  Every flight declares the same inertia uncertainty (--filter-inertia-std),
  as a user configures a fleet without knowing which vehicle file is wrong:
  the RMS of the inertia scale error over the plan's flights
  (plan_inertia_rel_rms; --inertia-std overrides it for every flight);
- cov_repairs: covariance repairs, summed;
- cov_checks / cov_not_pd: the filter's whole covariance checked for positive
  definiteness (Cholesky in double) at every NEES sample (every 10th control
  step, every flight), and the checks it failed;
- diverged_filter / diverged_oracle: flights the simulator stopped for
  divergence (exit 3) in each mode; `filter_only_diverged`: cases where the
  filter's flight diverged and the oracle's did not (`filter_only_diverged_cases`:
  their configurations, to fly again).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

VEHICLES = (("crazyflie-plus", 3), ("crazyflie-x", 3), ("hummingbird-plus", 2), ("hummingbird-x", 2),
            ("hexa-x", 1), ("octo-x", 1))
TRAJECTORIES = ("hover", "step", "circle", "lissajous")
# Effect ids with their default strength (propid_sitl --help).
EFFECTS = {
    "rotor_inertia": 1.0, "rotor_gyroscopic": 1.0, "rotor_drag": 1.0, "translational_lift": 1.0,
    "ground_effect": 1.0, "com_offset": 0.05, "inertia_error": 0.1, "esc_delay": 0.02,
    "thrust_nonlinearity": 0.1, "gyro_scale": 0.02, "aero_damping": 1.0,
}
# How a case draws its effects: the share of clean cases, the number of effects
# of a non-clean case (uniform over this tuple) and their strength (x U(low, high)).
CLEAN_SHARE = 0.3
EFFECT_COUNTS = (0, 0, 1, 1, 2)
EFFECT_STRENGTH = (0.5, 1.5)
# Fault classes with the log10 range of their rate per sample (time_jitter: std [us]).
FAULTS = {
    "esc_dropout": (-3.0, -0.7), "esc_spike": (-4.0, -2.0), "esc_stuck": (-4.0, -2.5),
    "esc_stale": (-4.0, -2.5), "gyro_spike": (-4.0, -2.0), "gyro_saturation": (-4.0, -2.5),
    "gyro_stuck": (-4.0, -2.5), "time_jitter": (0.5, 2.0), "time_repeat": (-4.0, -2.5),
    "time_backward": (-4.0, -2.5), "time_jump": (-4.5, -3.0),
}
# The Table 1 campaign's filter (priors = the truth distribution's, tight rate
# noise, no random walks) and the library default (propid_config_default).
CAMPAIGN_FLIGHT = ["--start-at-rest", "--coeff-spread", "0.2", "--gyro-bias-max", "0.0174533"]
CAMPAIGN_FILTER = ["--prior-kf-std", "0.11547", "--prior-km-std", "0.11547", "--prior-bias-std", "0.0100767",
                   "--prior-rate-std", "0.01", "--filter-rate-noise", "0.0004", "--filter-coeff-walk", "0.0",
                   "--filter-bias-walk", "0.0"]
# The truth distribution of every flight: kf, km = nominal x U(1-S, 1+S) per
# rotor, gyro bias U(-B, B) per axis, bias random walk W [rad/s/sqrt(s)] of the
# sensor set (propid_sitl --help).
COEFF_SPREAD = 0.2
GYRO_BIAS_MAX = math.radians(1.0)
GYRO_BIAS_WALK = {"paper": 0.0, "default": 1.0e-4}


def matched_filter(sensors: str, sensor_errors: bool = True) -> list[str]:
    """The "matched" tuning of the NEES flights: the library default, with the
    priors and random walks the truth is drawn from. A NEES is chi-square only
    when the filter's prior is the distribution of the truth: a uniform
    U(-a, a) has std a / sqrt(3); the coefficients are constant (walk 0); the
    bias walks as the sensor's. Rate process noise and gyro noise stay the
    library's and the datasheet's (design.md "Defaults"). The rotor-speed
    input's error terms come from the sensor model by one rule for every
    vehicle (propid_sitl --filter-sensor-errors: the telemetry's truncation
    error at the hover speed the rotors fly, the latency); sensor_errors False
    leaves them out (the inputs taken as
    exact, the tuning before that rule)."""
    walk = GYRO_BIAS_WALK[sensors]
    return (["--filter-sensor-errors"] if sensor_errors else []) + ["--coeff-spread", f"{COEFF_SPREAD}", "--gyro-bias-max", f"{GYRO_BIAS_MAX:.7g}",
            "--gyro-bias-walk", f"{walk}",
            "--prior-kf-std", f"{COEFF_SPREAD / math.sqrt(3.0):.6g}",
            "--prior-km-std", f"{COEFF_SPREAD / math.sqrt(3.0):.6g}",
            "--prior-bias-std", f"{GYRO_BIAS_MAX / math.sqrt(3.0):.6g}",
            "--filter-coeff-walk", "0", "--filter-bias-walk", f"{walk}"]


def plan_inertia_rel_rms() -> float:
    """RMS relative inertia scale error over the plan's flights: the inertia
    uncertainty a configuration of the whole fleet can honestly declare. A case
    carries inertia_error with probability (1 - CLEAN_SHARE) E[k] / len(EFFECTS)
    (k effects drawn without replacement), of strength nominal x U(low, high),
    whose mean square is nominal^2 (low^2 + low high + high^2) / 3."""
    low, high = EFFECT_STRENGTH
    share = (1.0 - CLEAN_SHARE) * (sum(EFFECT_COUNTS) / len(EFFECT_COUNTS)) / len(EFFECTS)
    mean_square = EFFECTS["inertia_error"] ** 2 * (low * low + low * high + high * high) / 3.0
    return math.sqrt(share * mean_square)


def plan_case(rng: random.Random, index: int, nees_tuning: str = "matched") -> dict:
    """One random flight configuration (flown in both modes)."""
    vehicle = rng.choices([v for v, _ in VEHICLES], weights=[w for _, w in VEHICLES])[0]
    trajectory = rng.choice(TRAJECTORIES)
    duration = round(rng.uniform(10.0, 60.0), 1)
    sensors = "paper" if rng.random() < 0.4 else "default"
    clean = rng.random() < CLEAN_SHARE  # fault-free, effect-free, no rotor loss: the NEES flights
    effects: list[str] = []
    faults: list[str] = []
    damage = None
    if not clean:
        for name in rng.sample(sorted(EFFECTS), rng.choice(EFFECT_COUNTS)):
            effects.append(f"{name}={EFFECTS[name] * rng.uniform(*EFFECT_STRENGTH):.4g}")
        for name in rng.sample(sorted(FAULTS), rng.choice((0, 1, 2, 3, 4))):
            low, high = FAULTS[name]
            faults.append(f"{name}={10.0 ** rng.uniform(low, high):.3g}")
        if rng.random() < 0.3:
            rotor = rng.randint(1, 4)
            damage = f"{rotor}@{rng.uniform(0.3, 0.7) * duration:.2f}={rng.uniform(0.1, 0.4):.3f}"
    # Tight (campaign) tuning only where it can hold: paper sensors, constant coefficients.
    tuning = "campaign" if sensors == "paper" and damage is None and rng.random() < 0.5 else "library"
    if clean:
        tuning = nees_tuning  # the NEES flights
    return {"case": index, "seed": 1000 + index, "vehicle": vehicle, "trajectory": trajectory,
            "duration_s": duration, "sensors": sensors, "tuning": tuning, "clean": clean,
            "effects": effects, "faults": faults, "damage": damage}


def command(sitl: str, case: dict, mode: str, summary: str, detect_damage: bool = True,
            inertia_std: float | None = None, gyro_stuck: int = 0) -> list[str]:
    """The propid_sitl command of one flight. inertia_std: the inertia
    uncertainty every flight declares (default plan_inertia_rel_rms());
    gyro_stuck: the filter's gyro_stuck_samples (0: off)."""
    cmd = [sitl, "--vehicle", case["vehicle"], "--trajectory", case["trajectory"], "--mode", mode,
           "--seed", str(case["seed"]), "--duration", str(case["duration_s"]), "--quiet",
           "--summary-json", summary, "--honesty-cov-check"]
    if case["sensors"] == "paper":
        cmd.append("--paper")
    if case["tuning"] == "campaign":
        cmd += CAMPAIGN_FLIGHT + CAMPAIGN_FILTER
    elif case["tuning"] == "matched":
        cmd += matched_filter(case["sensors"])
    elif case["tuning"] == "matched-exact-inputs":
        cmd += matched_filter(case["sensors"], sensor_errors=False)
    if case.get("rate_noise") is not None:  # a rate-noise rule's value (--nees-rate-rule)
        cmd += ["--filter-rate-noise", f"{case['rate_noise']:.6g}"]
    for effect in case["effects"]:
        cmd += ["--effect", effect]
    declared = plan_inertia_rel_rms() if inertia_std is None else inertia_std
    cmd += ["--filter-inertia-std", f"{declared:.6g}"]  # the same on every flight
    for fault in case["faults"]:
        cmd += ["--fault", fault]
    if case["damage"]:
        cmd += ["--damage", case["damage"]]
    if detect_damage:
        cmd.append("--detect-damage")
    if gyro_stuck:
        cmd += ["--filter-gyro-stuck", str(gyro_stuck)]
    return cmd


def fly(sitl: str, case: dict, mode: str, workdir: str, detect_damage: bool = True,
        inertia_std: float | None = None, gyro_stuck: int = 0) -> dict:
    summary = os.path.join(workdir, f"case{case['case']}-{mode}-{case['tuning']}.json")
    cmd = command(sitl, case, mode, summary, detect_damage, inertia_std, gyro_stuck)
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
    if proc.returncode not in (0, 3) or not os.path.exists(summary):
        return {"error": f"exit {proc.returncode}: {proc.stderr.strip()[-300:]}", "command": " ".join(cmd)}
    with open(summary, encoding="utf-8") as handle:
        data = json.load(handle)
    os.remove(summary)
    data["exit"] = proc.returncode
    return data


def expected_steps(case: dict) -> float:
    """Planned accepted gyro samples of one flight (for the plan and the progress bar)."""
    rate = 500.0 if case["sensors"] == "paper" else 1000.0
    return rate * case["duration_s"]


def percent(part: int, whole: int) -> float | None:
    return round(100.0 * part / whole, 2) if whole else None


def group_shares(group: list[int]) -> dict:
    """A group's [inside, samples, flights, below, above] NEES counts as shares of its samples."""
    inside, samples, flights, below, above = group
    return {"in_bounds_pct": percent(inside, samples), "below_bounds_pct": percent(below, samples),
            "above_bounds_pct": percent(above, samples), "samples": samples, "flights": flights}


def summarise(cases: list[dict], results: dict, elapsed_s: float, args) -> dict:
    out = {"steps": 0, "flights": 0, "cases": len(cases), "flown_s": 0.0,
           "faults_injected": {}, "nan_count": 0, "max_recovery_s": None, "rotor_losses": 0,
           "unrecovered": 0, "losses_from_accurate": 0, "recovered_from_accurate": 0,
           "lost_rotor_recovered": 0, "max_lost_rotor_recovery_s": None,
           "lost_rotor_from_accurate": 0, "lost_rotor_recovered_from_accurate": 0, "nees_in_bounds_pct": None,
           "nees_below_bounds_pct": None, "nees_above_bounds_pct": None, "nees_samples": 0, "nees_by_group": {},
           "false_converged": 0, "converged_claims": 0, "false_converged_pct": None,
           "false_converged_by_group": {}, "false_converged_flights": [], "nees_flights": [],
           "cov_repairs": 0, "cov_checks": 0, "cov_not_pd": 0, "model_mismatch_windows": 0, "diverged_filter": 0, "diverged_oracle": 0,
           "filter_only_diverged": 0, "filter_only_diverged_cases": [], "errors": []}
    nees_in = nees_below = nees_above = nees_all = 0
    groups: dict[str, list[int]] = {}
    false_groups: dict[str, list[int]] = {}
    for case in cases:
        pair = {}
        for mode in ("filter", "oracle"):
            data = results.get((case["case"], mode))
            if data is None:
                continue
            if "error" in data:
                out["errors"].append({"case": case, "mode": mode, **data})
                continue
            pair[mode] = data
            out["flights"] += 1
            out["steps"] += int(data.get("gyro_accepted", 0))
            out["flown_s"] += float(data.get("flown_s", 0.0))
            for name, count in data.get("faults_injected", {}).items():
                out["faults_injected"][name] = out["faults_injected"].get(name, 0) + int(count)
            honesty = data.get("honesty", {})
            out["nan_count"] += int(honesty.get("nonfinite_estimates", 0))
            out["cov_repairs"] += int(data.get("cov_repairs", 0))
            out["cov_checks"] += int(honesty.get("cov_checks", 0))
            out["cov_not_pd"] += int(honesty.get("cov_not_pd", 0))
            out["model_mismatch_windows"] += int(data.get("model_mismatch_windows", 0))
            if data["exit"] == 3:
                out["diverged_" + mode] += 1
            if mode != "filter":
                continue
            out["false_converged"] += int(honesty.get("false_converged", 0))
            out["converged_claims"] += int(honesty.get("converged_claims", 0))
            kind = "clean" if case["clean"] else ("effects" if case["effects"] else "no effect")
            key = f"{case['tuning']} tuning, {case['sensors']} sensors, {kind}"
            claims = false_groups.setdefault(key, [0, 0, 0])
            claims[0] += int(honesty.get("false_converged", 0))
            claims[1] += int(honesty.get("converged_claims", 0))
            claims[2] += 1
            if int(honesty.get("false_converged", 0)):
                out["false_converged_flights"].append({
                    "case": case["case"], "vehicle": case["vehicle"], "trajectory": case["trajectory"],
                    "sensors": case["sensors"], "tuning": case["tuning"], "effects": case["effects"],
                    "faults": case["faults"], "damage": case["damage"],
                    "false": int(honesty.get("false_converged", 0)), "claims": int(honesty.get("converged_claims", 0))})
            out["rotor_losses"] += int(honesty.get("coefficient_changes", 0))
            out["unrecovered"] += int(honesty.get("unrecovered", 0))
            recovery = honesty.get("max_recovery_s")
            if recovery is not None:
                out["max_recovery_s"] = max(out["max_recovery_s"] or 0.0, float(recovery))
            out["losses_from_accurate"] += int(honesty.get("changes_from_inside", 0))
            out["recovered_from_accurate"] += int(honesty.get("recovered_from_inside", 0))
            out["lost_rotor_recovered"] += int(honesty.get("changed_rotor_recovered", 0))
            out["lost_rotor_from_accurate"] += int(honesty.get("changed_rotor_from_inside", 0))
            out["lost_rotor_recovered_from_accurate"] += int(honesty.get("changed_rotor_recovered_from_inside", 0))
            recovery = honesty.get("max_changed_rotor_recovery_s")
            if recovery is not None:
                out["max_lost_rotor_recovery_s"] = max(out["max_lost_rotor_recovery_s"] or 0.0, float(recovery))
            if case["clean"] and data["exit"] == 0:
                inside, samples = int(honesty.get("nees_in_bounds", 0)), int(honesty.get("nees_samples", 0))
                below, above = int(honesty.get("nees_below_bounds", 0)), int(honesty.get("nees_above_bounds", 0))
                nees_in += inside
                nees_below += below
                nees_above += above
                nees_all += samples
                key = f"{case['tuning']} tuning, {case['sensors']} sensors"
                group = groups.setdefault(key, [0, 0, 0, 0, 0])
                group[0] += inside
                group[1] += samples
                group[2] += 1
                group[3] += below
                group[4] += above
                out["nees_flights"].append({
                    "case": case["case"], "vehicle": case["vehicle"], "trajectory": case["trajectory"],
                    "duration_s": case["duration_s"], "sensors": case["sensors"], "tuning": case["tuning"],
                    "rate_noise": case.get("rate_noise"),
                    "dof": int(honesty.get("nees_dof", 0)), "nees_mean": honesty.get("nees_mean"),
                    "in_bounds_pct": percent(inside, samples), "below_bounds_pct": percent(below, samples),
                    "above_bounds_pct": percent(above, samples),
                    "first_all_claimed_s": honesty.get("first_all_claimed_s"),
                    "all_claimed_at_end": bool(honesty.get("all_claimed_at_end", 0)),
                    "false_converged": int(honesty.get("false_converged", 0)),
                    "converged_claims": int(honesty.get("converged_claims", 0))})
        if pair.get("filter", {}).get("exit") == 3 and pair.get("oracle", {}).get("exit") == 0:
            out["filter_only_diverged"] += 1
            out["filter_only_diverged_cases"].append({
                key: case[key] for key in ("case", "seed", "vehicle", "trajectory", "duration_s", "sensors",
                                           "tuning", "effects", "faults", "damage")})
    # The same clean flights with the inputs taken as exact, flown in the same run.
    exact: dict[str, list[int]] = {}
    for case in cases:
        data = results.get((case["case"], "exact-inputs"))
        if not case["clean"] or data is None or "error" in data or data.get("exit") != 0:
            continue
        honesty = data.get("honesty", {})
        group = exact.setdefault(f"{case['sensors']} sensors", [0, 0, 0, 0, 0])
        group[0] += int(honesty.get("nees_in_bounds", 0))
        group[1] += int(honesty.get("nees_samples", 0))
        group[2] += 1
        group[3] += int(honesty.get("nees_below_bounds", 0))
        group[4] += int(honesty.get("nees_above_bounds", 0))
    if exact:
        inside, samples = sum(g[0] for g in exact.values()), sum(g[1] for g in exact.values())
        out["nees_exact_inputs"] = {
            "in_bounds_pct": round(100.0 * inside / samples, 2) if samples else None,
            **{key: group_shares(g) for key, g in sorted(exact.items())}}
    out["nees_samples"] = nees_all
    out["nees_in_bounds_pct"] = percent(nees_in, nees_all)
    out["nees_below_bounds_pct"] = percent(nees_below, nees_all)
    out["nees_above_bounds_pct"] = percent(nees_above, nees_all)
    out["nees_by_group"] = {key: group_shares(g) for key, g in sorted(groups.items())}
    # Honest flights (the clean ones): do they still claim convergence, and when?
    firsts = sorted(f["first_all_claimed_s"] for f in out["nees_flights"] if f["first_all_claimed_s"] is not None)
    fractions = sorted(f["first_all_claimed_s"] / f["duration_s"] for f in out["nees_flights"]
                       if f["first_all_claimed_s"] is not None)
    out["clean_flights_claims"] = {
        "flights": len(out["nees_flights"]),
        "all_claimed_once": len(firsts),
        "all_claimed_at_end": sum(1 for f in out["nees_flights"] if f["all_claimed_at_end"]),
        "first_all_claimed_s_median": firsts[len(firsts) // 2] if firsts else None,
        "first_all_claimed_s_max": firsts[-1] if firsts else None,
        "first_all_claimed_fraction_of_flight_median": round(fractions[len(fractions) // 2], 3) if fractions else None}
    out["false_converged_by_group"] = {
        key: {"false": g[0], "claims": g[1], "flights": g[2]} for key, g in sorted(false_groups.items())}
    if out["converged_claims"]:
        out["false_converged_pct"] = round(100.0 * out["false_converged"] / out["converged_claims"], 3)
    out["flown_s"] = round(out["flown_s"], 1)
    out["wall_time_s"] = round(elapsed_s, 1)
    out["jobs"] = args.jobs
    out["plan_seed"] = args.seed
    out["inertia_rel_std_declared"] = round(plan_inertia_rel_rms() if args.inertia_std is None
                                            else args.inertia_std, 6)
    out["command"] = (f"make soak SOAK_STEPS={args.steps:g} SOAK_SEED={args.seed} JOBS={args.jobs}"
                      + (f" SOAK_NEES_TUNING={args.nees_tuning}" if args.nees_tuning != "matched" else "")
                      + (f" SOAK_NEES_RATE_RULE={args.nees_rate_rule}" if args.nees_rate_rule != "none" else "")
                      + (f" SOAK_NEES_DEFAULT_RATE_NOISE={args.nees_default_rate_noise:g}"
                         if args.nees_default_rate_noise is not None else "")
                      + (f" SOAK_INERTIA_STD={args.inertia_std:g}" if args.inertia_std is not None else "")
                      + f" SOAK_GYRO_STUCK={args.gyro_stuck}")
    out["gyro_stuck_samples"] = args.gyro_stuck
    out["nees_rate_rule"] = args.nees_rate_rule
    out["nees_default_rate_noise"] = args.nees_default_rate_noise
    return out


def set_default_sensor_rate_noise(cases: list[dict], rate_noise: float) -> None:
    """--nees-default-rate-noise: the NEES cases with the default sensors fly this rate noise."""
    for case in cases:
        if case["clean"] and case["sensors"] == "default":
            case["rate_noise"] = rate_noise


def calibrate_cases(cases: list[dict], args) -> None:
    """--nees-rate-rule: each NEES case the rule applies to gets its rate noise from its
    calibration flight (tests/soak/rate_noise_rule.py, calibrate; not counted in any figure).
    A calibration flight that fails leaves the case at the matched tuning, and says so."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import rate_noise_rule

    def command_of(flight: dict, summary: str) -> list[str]:
        return command(args.sitl, flight, "filter", summary, not args.no_detect_damage, args.inertia_std,
                       args.gyro_stuck)

    chosen = [case for case in cases if rate_noise_rule.rule_applies(args.nees_rate_rule, case)]
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        for case, found in zip(chosen, pool.map(lambda c: rate_noise_rule.calibrate(c, command_of), chosen)):
            if "error" in found:
                print(f"soak: case {case['case']}: {found['error']}; matched tuning kept", file=sys.stderr)
            else:
                case["rate_noise"] = found["q_rate"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sitl", required=True, help="propid_sitl executable")
    parser.add_argument("--steps", type=float, default=1e7, help="filter steps to fly (default 1e7)")
    parser.add_argument("--jobs", type=int, default=2, help="parallel flights (default 2)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the flight plan (default 1)")
    parser.add_argument("--out", default="build/results/soak.json", help="JSON figures")
    parser.add_argument("--no-detect-damage", action="store_true",
                        help="fly without the firmware's damage detector (propid_damage; default: with it)")
    parser.add_argument("--nees-tuning", choices=("matched", "library"), default="matched",
                        help="filter tuning of the fault-free, effect-free NEES flights: matched (priors and "
                             "walks = the truth's distribution, default) or library (propid_config_default)")
    parser.add_argument("--inertia-std", type=float, default=None,
                        help="inertia_rel_std declared by every flight (default: the RMS inertia scale error "
                             f"over the plan's flights, {plan_inertia_rel_rms():.4f})")
    parser.add_argument("--nees-rate-rule", choices=("none", "previous-flight"), default="none",
                        help="rate process noise of the NEES flights with exact rotor speeds (paper sensors): "
                             "none (the matched tuning's, default) or previous-flight (the q_rate derived from a "
                             "previous flight of the same vehicle and mission, tests/soak/rate_noise_rule.py)")
    parser.add_argument("--nees-default-rate-noise", type=float, default=None, metavar="Q",
                        help="rate process noise of the NEES flights with the default sensors (DShot telemetry) "
                             "[rad/s^2/sqrt(Hz)] (default: the matched tuning's, the library's 0.2)")
    parser.add_argument("--gyro-stuck", type=int, default=0, metavar="N",
                        help="the filter's gyro_stuck_samples on every flight: a gyro axis repeating its "
                             "reading bit for bit N times in a row is not fused (0: off, default; >= 2 on; "
                             "docs/reliability.md 'A stuck gyro axis')")
    args = parser.parse_args(argv)
    if not os.access(args.sitl, os.X_OK):
        print(f"soak: {args.sitl}: not an executable (run make host)", file=sys.stderr)
        return 2
    if args.steps <= 0 or args.jobs < 1 or (args.inertia_std is not None and not 0.0 <= args.inertia_std <= 1.0) \
            or args.gyro_stuck == 1 or not 0 <= args.gyro_stuck <= 65535 \
            or (args.nees_default_rate_noise is not None and not 0.0 <= args.nees_default_rate_noise <= 1e4):
        print("soak: --steps must be > 0, --jobs >= 1, --inertia-std in [0, 1], --gyro-stuck 0 or 2..65535 and "
              "--nees-default-rate-noise in [0, 1e4]", file=sys.stderr)
        return 2

    rng = random.Random(args.seed)
    cases: list[dict] = []
    planned = 0.0
    # 5 % over: rejected samples (faults) are not steps, and the plan must reach --steps.
    while planned < 1.05 * args.steps:
        case = plan_case(rng, len(cases), args.nees_tuning)
        cases.append(case)
        planned += 2.0 * expected_steps(case)

    if args.nees_rate_rule != "none":
        calibrate_cases(cases, args)
    if args.nees_default_rate_noise is not None:
        set_default_sensor_rate_noise(cases, args.nees_default_rate_noise)

    try:
        from tqdm import tqdm
    except ImportError:  # the venv has it; plain runs without a bar
        tqdm = None
    bar = tqdm(total=int(planned), unit="step", unit_scale=True, desc="soak", file=sys.stderr) if tqdm else None
    results: dict = {}
    start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="propid-soak-") as workdir, \
            ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futures = {pool.submit(fly, args.sitl, case, mode, workdir, not args.no_detect_damage,
                               args.inertia_std, args.gyro_stuck): (case, mode)
                   for case in cases for mode in ("filter", "oracle")}
        if args.nees_tuning == "matched":
            # Side by side: each NEES flight again with its inputs taken as exact
            # (figures nees_exact_inputs; not counted in steps or any other figure).
            for case in cases:
                if case["clean"]:
                    twin = {**case, "tuning": "matched-exact-inputs"}
                    futures[pool.submit(fly, args.sitl, twin, "filter", workdir, not args.no_detect_damage,
                                        args.inertia_std, args.gyro_stuck)] = (case, "exact-inputs")
        try:
            for future in as_completed(futures):
                case, mode = futures[future]
                try:
                    results[(case["case"], mode)] = future.result()
                except subprocess.TimeoutExpired:
                    results[(case["case"], mode)] = {"error": "timeout", "command": ""}
                if bar and mode != "exact-inputs":
                    bar.update(int(expected_steps(case)))
        except KeyboardInterrupt:
            for future in futures:
                future.cancel()
            print("\nsoak: interrupted; figures of the flights flown so far", file=sys.stderr)
    if bar:
        bar.close()
    figures = summarise(cases, results, time.monotonic() - start, args)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(figures, indent=2) + "\n", encoding="utf-8")
    width = max(len(k) for k in figures)
    for key, value in figures.items():
        if key in ("errors", "nees_flights", "false_converged_flights", "filter_only_diverged_cases"):
            value = len(value)
        print(f"{key:<{width}}  {json.dumps(value) if isinstance(value, (dict, list)) else value}")
    print(f"soak: {args.out}")
    return 1 if figures["errors"] or figures["nan_count"] else 0


if __name__ == "__main__":
    sys.exit(main())
