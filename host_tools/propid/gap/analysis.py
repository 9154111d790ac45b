"""The gap diagnosis, start to end: prepare, align, base fit, select effects, where,
how far, corrected vehicle. Returns the OUT.json dictionary (plus arrays for plots)."""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.gap import alignment, basefit, coherence, explainable, scoring, selection, shrink, significance, where, whitening
from propid.gap.vehicle_out import corrected_vehicle
from propid.gap.design import base_columns, build_design, responses
from propid.gap.effects import (ALL_IDS, CONDITIONED_ON, EFFECTS, ESC_DELAY, MIN_REPORTED_LAG_S, RESIDUAL_LAG,
                               Context, by_id)
from propid.gap.log_order import canonical_order
from propid.gap.prep import Band, Flight, columns_present, difference_response, prepare_flight
from propid.realdata_checks import bandpass

NEEDS_TEXT = {"inertia": "vehicle inertia", "acc": "acc_x/y/z", "mass": "vehicle mass", "attitude": "qw/qx/qy/qz", "velocity": "vx/vy/vz",
              "height": "pz", "rotor_radius": "vehicle rotor_radius", "cmd": "cmd_i", "vbat": "vbat"}


ALIGNMENT_NUISANCE = ("rotor_gyroscopic", "rotor_drag", "com_offset", "aero_damping")
LAG_NUISANCE_MODES = ("logged", "shifted")
SCALE_LIKE = ("inertia_error", "gyro_scale", "thrust_nonlinearity")  # effects a regressor attenuation mimics
# A lag up to one log sample is the logging convention (each stream's latest sample in a
# row), not a telemetry delay; below 5 ms the sensor chain's own lags (gyro filtering) rule.
MIN_REPORTED_DELAY_S = MIN_REPORTED_LAG_S
MIN_DELAY_EXPLAINED = 0.02  # 2 % of the torque residual held out (raw rows; whitened with lag_evidence "whitened")


@dataclass
class Options:
    band: Band
    progress: bool = True
    auto_highpass: bool = False
    repeats: str = "samples"  # copies of the previous row in the fits: "samples", or "missing" (evaluated; prep.py)
    # the stream lag's held-out evidence: "raw" (2 s blocks of the band-passed rows, the default) or
    # "whitened" (the effects' replication test on whitened rows; evaluated, docs/gap.md "Stream alignment")
    lag_evidence: str = "raw"
    # ground_effect's height: "com" (pz for every rotor, the default) or "hub" (each rotor's hub height
    # from the attitude; evaluated, not the default: docs/gap.md "Effect library")
    ground_effect_height: str = "com"
    # the effects' held-out replication statistic: "improvement" (the held-out SSE reduction, the
    # default) or "prediction" (the held-out residual along the effect's training-fold prediction;
    # evaluated, not the default: docs/gap.md, SITL accuracy "The score test again")
    replication: str = "improvement"
    # the replication's folds with one or two logs: "time" (1 s blocks, index mod 5, the default) or
    # "excitation" (a 1 s block with more than a fold's share of the effect's regressor energy split
    # over the folds; evaluated, not the default: docs/gap.md, SITL accuracy "Folds balanced by excitation")
    replication_folds: str = "time"
    # the block folds with one or two logs (scoring.fold_partitions): "first-row" (one partition
    # numbered across the logs in canonical order, the default) or "phases" (1 s groups numbered within
    # each log from its own start, five partitions with grids offset by 0.2 s, held-out sums averaged;
    # an option, evaluated: docs/gap.md, Scoring "Folds")
    block_folds: str = scoring.BLOCK_FOLDS
    # the gyro's constant bias before the measured torque: "off" (the default) or "attitude" (measured
    # against the logged attitude; evaluated, not the default: docs/gap.md "Data preparation")
    gyro_bias: str = "off"
    # the alignment's nuisance columns (rotor_gyroscopic, rotor_drag, com_offset, aero_damping): "logged"
    # (built once from the logged rotor stream, the default) or "shifted" (built at each candidate lag from
    # the stream shifted by it; evaluated, not the default: docs/gap.md "Stream alignment")
    lag_nuisance: str = "logged"
    # the held-out residual's predictable share from the logged signals and the gyro-noise floor
    # (explainable.py; a diagnostic, off by default: docs/gap.md "How far")
    explainable: bool = False


HIGHPASS_CANDIDATES_HZ = (0.2, 0.5, 1.0, 2.0, 5.0)
ALIGNMENT_HIGHPASS_CANDIDATES_HZ = (0.2, 0.5, 1.0, 2.0)  # the band the stream lag is searched in
BAND_STABILITY = 0.10
MIN_CANCELLATION_BLOCKS = 4  # fewer 2 s blocks give a bootstrap interval of a handful of values
MIN_BAND_OCTAVES = 2.0  # a candidate high-pass leaves at least two octaves below the low-pass
CLOSED_LOOP = "closed_loop_cancellation"


def highpass_candidates(flights: list[Flight], band: Band,
                        candidates: tuple[float, ...] = HIGHPASS_CANDIDATES_HZ) -> tuple[float, ...]:
    top = min(band.for_rate(f.rate_hz).lowpass_hz for f in flights)
    return tuple(h for h in candidates if h * 2.0**MIN_BAND_OCTAVES <= top) or candidates[:1]


def choose_highpass(flights: list[Flight], vehicle: Vehicle, band: Band,
                    candidates: tuple[float, ...] = HIGHPASS_CANDIDATES_HZ) -> tuple[Band, dict]:
    """Closed-loop bias shows as a torque coefficient that depends on the band's lower
    edge: the controller cancels slow unmodelled torques, which drags the coefficient of
    a band reaching down to them towards 0. Rule: the lowest candidate high-pass whose
    roll/pitch fleet kf (least squares, mean of the two axes) is not shown to be more than
    BAND_STABILITY below the kf at a higher candidate: a lower band is given up only when
    the 95 % paired block-bootstrap interval of the ratio kf(low)/kf(high) lies entirely
    below 1 - BAND_STABILITY (a noisy short log must not lose its slow content to scatter,
    and a low band reading MORE than a high one is not the closed-loop signature: a narrow
    high band is the attenuated one then); the highest candidate otherwise. Only a higher
    candidate whose own kf is shown > 0 (its 95 % bootstrap interval above 0) judges the lower
    ones (Fieller: a ratio to a denominator that may be 0 has no bounded interval; a rotor stream
    lagging by more than half a period reverses a high band's torque fit)."""
    candidates = highpass_candidates(flights, band, candidates)
    values, boots = {}, {}
    for hp in candidates:
        trial = [replace(f, band=replace(band, highpass_hz=hp).for_rate(f.rate_hz)) for f in flights]
        kf, boot = [], []
        for axis in ("roll", "pitch"):
            fit = basefit.fleet_fit(trial, axis, vehicle.positions, vehicle.yaw_signs, vehicle.mass,
                                    use_instrument=False, keep_bootstrap=True)
            kf.append(fit["least_squares_value"])
            boot.append(fit["bootstrap"])
        values[hp] = float(np.mean(kf))
        boots[hp] = np.mean(boot, axis=0)
    intervals = {}
    for k, hp in enumerate(candidates):
        for h in candidates[k + 1:]:
            ratio = boots[hp] / np.where(boots[h] != 0, boots[h], np.nan)
            ratio = ratio[np.isfinite(ratio)]
            intervals[(hp, h)] = ([float(np.percentile(ratio, 2.5)), float(np.percentile(ratio, 97.5))]
                                  if ratio.size else [float("nan")] * 2)

    # Fieller: a ratio whose denominator's interval reaches 0 has no bounded interval, so a
    # band whose kf is not shown > 0 (a lag or noise reversing its torque) cannot judge the
    # bands below it
    kf_ci = {h: [float(np.percentile(boots[h], 2.5)), float(np.percentile(boots[h], 97.5))] for h in candidates}
    positive = {h: bool(np.isfinite(kf_ci[h][0]) and kf_ci[h][0] > 0) for h in candidates}

    def differs(lo_hp, hi_hp):
        if not positive[hi_hp]:
            return False
        lo, hi = intervals[(lo_hp, hi_hp)]
        if not (np.isfinite(lo) and np.isfinite(hi)):
            return True
        return hi < 1.0 - BAND_STABILITY

    chosen = candidates[-1]
    for k, hp in enumerate(candidates):
        if not any(differs(hp, h) for h in candidates[k + 1:]):
            chosen = hp
            break
    return replace(band, highpass_hz=chosen), {
        "candidates_hz": list(candidates),
        "roll_pitch_kf": [values[h] for h in candidates],
        "roll_pitch_kf_ci": [kf_ci[h] for h in candidates],
        "kf_shown_positive": [positive[h] for h in candidates],
        "ratio_boot": {h: boots[h] / np.where(boots[chosen] != 0, boots[chosen], np.nan) for h in candidates},
        "ratio_ci_to_higher": {f"{a:g}/{b:g}": v for (a, b), v in intervals.items()},
        "chosen_hz": chosen,
        "rule": "lowest high-pass whose roll/pitch kf is not shown (95 % paired block bootstrap of the "
                "ratio) to be more than 10 % below the kf at a higher candidate whose own kf is shown > 0 "
                "(Fieller: a ratio to a kf that may be 0 is unbounded); run on the aligned logs; "
                "candidates leave two octaves below the low-pass"}


class Progress:
    """The analysis' progress bar. Stages whose length is known only later (the effect
    selection stops when nothing more is significant; the replays depend on the options)
    reserve their most steps with `grow` and, when done early, jump to the stage's end with
    `fill_to`, so the bar ends at its total instead of stopping part-way."""

    def __init__(self, enabled: bool, total: int):
        self.bar = None
        if enabled:
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc="gap", unit="step", leave=False)

    def __call__(self, n: int = 1):
        if self.bar is not None:
            self.bar.update(n)

    def grow(self, n: int):
        """Reserve n more steps (a stage whose length is now known)."""
        if self.bar is not None and n > 0:
            self.bar.total += n
            self.bar.refresh()

    def position(self) -> int:
        return int(self.bar.n) if self.bar is not None else 0

    def fill_to(self, mark: int):
        """Advance to `mark` (a stage that ended before its most steps)."""
        if self.bar is not None and mark > self.bar.n:
            self.bar.update(mark - self.bar.n)

    def close(self):
        if self.bar is not None:
            self.fill_to(int(self.bar.total))
            self.bar.close()


def shifted_flight(f: Flight, delay: float) -> Flight:
    if delay == 0:
        return f
    return replace(f, speed=f.shifted(f.speed, delay), speed_dot=f.shifted(f.speed_dot, delay))


def make_context(flights: list[Flight], vehicle: Vehicle, kf: np.ndarray, km: np.ndarray) -> Context:
    speeds = np.concatenate([f.speed[np.concatenate([np.arange(a, b) for a, b in f.segs])] for f in flights])
    return Context(positions=vehicle.positions, yaw_signs=vehicle.yaw_signs, kf=kf, km=km, mass=vehicle.mass,
                   inertia=np.asarray(vehicle.inertia, dtype=float), rotor_radius=vehicle.rotor_radius,
                   speed_ref=float(np.median(speeds)), sample_period_s=1.0 / min(f.rate_hz for f in flights))


def testable(present: dict, vehicle: Vehicle) -> tuple[list[str], list[dict]]:
    ok, missing = [], []
    for e in EFFECTS:
        lacking = [NEEDS_TEXT[n] for n in e.needs if not present.get(n)]
        if lacking:
            missing.append({"id": e.id, "missing": lacking})
        else:
            ok.append(e.id)
    return ok, missing



def _alignment_nuisance(f: Flight, ctx: Context, candidates: list[str]) -> dict:
    """Roll/pitch columns of the effects that do not depend on the rotor stream's timing
    (alignment.py fits them with every lag)."""
    cols = {"roll": [], "pitch": []}
    for eid in ALIGNMENT_NUISANCE:
        if eid not in candidates:
            continue
        built = by_id(eid).build(f, ctx)
        for a in cols:
            cols[a].append(built[a] if a in built else np.zeros((len(f.t), len(by_id(eid).params))))
    return {a: np.column_stack(v) if v else np.zeros((len(f.t), 0)) for a, v in cols.items()}


def _nuisance_at(flights: list[Flight], ctx: Context, candidates: list[str], mode: str):
    """None ("logged": the alignment fits the nuisance columns of the logged stream at every lag) or,
    "shifted", d -> each flight's nuisance columns built from its rotor stream shifted by d."""
    if mode == "logged":
        return None
    if mode != "shifted":
        raise UserError(f"lag_nuisance {mode!r}: choose one of {', '.join(LAG_NUISANCE_MODES)}")
    return lambda d: [_alignment_nuisance(shifted_flight(f, d), ctx, candidates) for f in flights]


def per_log_alignment(flights: list[Flight], held: list[Flight], vehicle: Vehicle, candidates: list[str],
                      evidence: bool = False, lag_nuisance: str = "logged",
                      block_folds: str = scoring.BLOCK_FOLDS) -> list[dict]:
    """Each log's own rotor-stream lag (the same search as the pooled one, on that log
    alone): the lag belongs to a log's telemetry schedule, not to the vehicle. A held-out
    log's lag is measured on its own stream, as the filter's per-log delay rule does; the
    model coefficients evaluated on it still come from the fitted logs only. `evidence`: also
    each log's own held-out evidence on its whitened rows (alignment.whitened_evidence)."""
    out = []
    for f in flights + held:
        ctx = make_context([f], vehicle, np.ones(vehicle.rotor_count), np.ones(vehicle.rotor_count))
        one = alignment.search([f], vehicle.positions, vehicle.yaw_signs,
                               nuisance=[_alignment_nuisance(f, ctx, candidates)], evidence=evidence,
                               nuisance_at=_nuisance_at([f], ctx, candidates, lag_nuisance),
                               block_folds=block_folds)
        out.append({"delay_s": float(one["delay_s"]), **({"whitened": one["whitened"]} if evidence else {})})
    return out


def per_log_lag_decision(per_log: list[dict], names: list[str], fitted: int, sample_period: float) -> dict:
    """--lag-evidence whitened with several logs: a log is aligned by its own lag when that
    lag's own held-out evidence (its whitened rows) passes Holm's step-down at
    alignment.EVIDENCE_LEVEL over all the logs (fitted and held out), else it is left at 0;
    esc_delay is significant when a fitted log's lag passes and clears the reporting floors
    (explained fraction, |d| above a sample and 5 ms). The entry's evidence is the fitted log
    with the smallest p-value."""
    p_values = [e["whitened"]["p_value"] for e in per_log]
    shown = significance.holm(p_values, alignment.EVIDENCE_LEVEL)
    delays = [e["delay_s"] if ok else 0.0 for e, ok in zip(per_log, shown)]
    floor = max(sample_period, MIN_REPORTED_DELAY_S)
    significant = any(shown[k] and per_log[k]["whitened"]["explained_fraction"] >= MIN_DELAY_EXPLAINED
                      and abs(per_log[k]["delay_s"]) > floor for k in range(fitted))
    strongest = min(range(fitted), key=lambda k: p_values[k])
    table = {name: {"delay_s": e["delay_s"], "explained_fraction": e["whitened"]["explained_fraction"],
                    "held_out_weighted_fraction": e["whitened"]["held_out_weighted_fraction"],
                    "ci": e["whitened"]["ci"], "p_value": e["whitened"]["p_value"], "aligned": ok,
                    "role": "fit" if k < fitted else "holdout"}
             for k, (name, e, ok) in enumerate(zip(names, per_log, shown))}
    return {"delays": delays, "shown": any(shown[:fitted]), "significant": significant,
            "evidence": {**per_log[strongest]["whitened"], "log": names[strongest]}, "per_log": table}


def _physical(design, theta_scaled, effect_id, ctx):
    cols = design.groups[effect_id]
    coef = np.asarray(theta_scaled) / design.scale[cols]
    e = by_id(effect_id)
    return e.physical(coef, ctx) if e.physical else {p: float(v) for p, v in zip(e.params, coef)}


def run(logs: list[FlightLog], vehicle: Vehicle, holdout: list[FlightLog], options: Options) -> dict:
    # one order whatever the command line's: bootstraps and sums follow the list (log_order.py)
    logs, holdout = canonical_order(logs), canonical_order(holdout)
    unit_inertia = vehicle.inertia is None
    original_vehicle = vehicle
    if unit_inertia:  # torque coefficients become kf/J-like ratios in the file's geometry
        vehicle = copy.deepcopy(vehicle)
        vehicle.inertia = np.eye(3)
    progress = Progress(options.progress, total=60)  # + the selection's steps, reserved below
    hub = options.ground_effect_height == "hub"
    flights = [prepare_flight(log, vehicle, options.band, repeats=options.repeats, attitude=hub,
                              gyro_bias=options.gyro_bias) for log in logs]
    band_rule = None
    requested_band = options.band
    if options.auto_highpass:  # the band the stream lag is searched in (the rule on unaligned logs)
        search_band, _ = choose_highpass(flights, vehicle, options.band, ALIGNMENT_HIGHPASS_CANDIDATES_HZ)
        flights = [replace(f, band=search_band.for_rate(f.rate_hz)) for f in flights]
    else:
        search_band = options.band
    held_flights = [prepare_flight(log, vehicle, search_band, repeats=options.repeats, attitude=hub,
                                   gyro_bias=options.gyro_bias)
                    for log in holdout]
    progress(5)
    present = columns_present(logs + holdout, vehicle)
    with_thrust = bool(present["acc"] and present["mass"])
    present["inertia"] = not unit_inertia
    candidates, untestable = testable(present, vehicle)

    # 1. stream alignment (esc_delay)
    ctx_align = make_context(flights, vehicle, np.ones(vehicle.rotor_count), np.ones(vehicle.rotor_count))
    nuisance = [_alignment_nuisance(f, ctx_align, candidates) for f in flights]
    whitened = options.lag_evidence == "whitened"
    align = alignment.search(flights, vehicle.positions, vehicle.yaw_signs, progress=lambda: progress(0), nuisance=nuisance,
                             evidence=whitened,
                             nuisance_at=_nuisance_at(flights, ctx_align, candidates, options.lag_nuisance),
                             block_folds=options.block_folds)
    progress(20)
    # the alignment is always applied (stream misalignment is part of the base fit); it is
    # reported as esc_delay when it is significant and longer than the log's sample period
    sample_period = 1.0 / min(f.rate_hz for f in flights)
    # the lag's held-out evidence: the raw rows' interval above 0, or (lag_evidence "whitened") the
    # effects' replication test on whitened rows (alignment.whitened_evidence)
    evidence = align["whitened"] if whitened else {"explained_fraction": align["explained_fraction"], "ci": align["ci"]}
    shown = bool(evidence["p_value"] <= alignment.EVIDENCE_LEVEL) if whitened else bool(align["ci"][0] > 0)
    delay_significant = bool(shown and evidence["explained_fraction"] >= MIN_DELAY_EXPLAINED
                             and abs(align["delay_s"]) > max(sample_period, MIN_REPORTED_DELAY_S))
    delay = align["delay_s"] if shown else 0.0
    # several logs: each log aligned by its own lag when the pooled one is applied
    delays = [delay] * (len(flights) + len(held_flights))
    names = [f.name for f in flights + held_flights]
    if whitened and len(names) > 1:
        # a lag belongs to a log: each log's own lag on its own whitened rows (per_log_lag_decision),
        # not one pooled lag tested on whole held-out logs
        decision = per_log_lag_decision(per_log_alignment(flights, held_flights, vehicle, candidates, evidence=True,
                                                          lag_nuisance=options.lag_nuisance,
                                                          block_folds=options.block_folds),
                                        names, len(flights), sample_period)
        delays, shown, delay_significant = decision["delays"], decision["shown"], decision["significant"]
        evidence = decision["evidence"]
        align["per_log_delay_s"] = dict(zip(names, delays))
        align["per_log_evidence"] = decision["per_log"]
    elif delay and len(names) > 1:
        delays = [e["delay_s"] for e in per_log_alignment(flights, held_flights, vehicle, candidates,
                                                          lag_nuisance=options.lag_nuisance,
                                                          block_folds=options.block_folds)]
        align["per_log_delay_s"] = dict(zip(names, delays))
    work = [shifted_flight(f, d) for f, d in zip(flights, delays)]
    work_held = [shifted_flight(f, d) for f, d in zip(held_flights, delays[len(flights):])]
    # the band rule again, on the aligned logs and with the 5 Hz candidate: a misaligned rotor
    # stream reads a torque fit that falls with frequency, which would hide the closed loop's
    # rise above its bandwidth
    if options.auto_highpass:
        band, band_rule = choose_highpass(work, vehicle, requested_band)
        options = replace(options, band=band, auto_highpass=False)
        flights, held_flights, work, work_held = ([replace(f, band=band.for_rate(f.rate_hz)) for f in group]
                                                  for group in (flights, held_flights, work, work_held))

    # 2. base model: per-rotor kf (shared by thrust and torques), per-rotor km
    count = vehicle.rotor_count
    kf0 = np.full(count, 1.0)
    km0 = np.full(count, 1.0)
    ctx0 = make_context(work, vehicle, kf0, km0)
    base_design = build_design(work, ctx0, [], vehicle.mass, with_thrust)
    gr0 = scoring.grams(base_design, block_folds=options.block_folds)
    base_cols = base_design.groups["base"]
    gr0.weight = scoring.axis_weights(base_design, base_cols)
    theta = scoring.solve(gr0, base_cols, np.arange(base_design.n_blocks)) / base_design.scale[base_cols]
    kf_rotor, km_rotor = theta[:count], theta[count:]
    progress(5)

    # 3. candidate effects on top of the base model
    ctx = make_context(work, vehicle, kf_rotor, km_rotor)
    ctx.inertia_known = not unit_inertia
    effects = [by_id(e) for e in candidates]
    # nuisance columns some candidates are tested on top of (selection.score); not candidates
    nuisances = [RESIDUAL_LAG] if any(CONDITIONED_ON.get(e) == RESIDUAL_LAG.id for e in candidates) else []
    design = build_design(work, ctx, effects + nuisances, vehicle.mass, with_thrust)
    gr = scoring.grams(design, block_folds=options.block_folds)
    gr.weight = gr0.weight
    # effects are scored on the whitened rows (generalised least squares, whitening.py)
    # the noise spectrum comes from the residual of the full model (base + every candidate), so
    # that an effect's own signature is not taken for noise and whitened away
    nuisance_cols = {c for e in nuisances for c in design.groups[e.id]}
    all_cols = [c for c in range(len(design.names)) if c not in nuisance_cols]
    full_residual = scoring.residuals(design, all_cols, scoring.solve(gr, all_cols, np.arange(design.n_blocks)))
    design_w, _ = whitening.whiten(design, full_residual, [f.rate_hz for f in work],
                                   [(f.band.highpass_hz, f.band.lowpass_hz) for f in work])
    gr_w = scoring.grams(design_w, block_folds=options.block_folds)
    gr_w.weight = scoring.axis_weights(design_w, base_cols)
    progress(10)
    # the selection scores every remaining candidate per round, at most MAX_EFFECTS rounds
    selection_steps = sum(max(len(candidates) - r, 0) for r in range(selection.MAX_EFFECTS))
    progress.grow(selection_steps)
    selection_end = progress.position() + selection_steps
    sel = selection.forward_select(design_w, gr_w, candidates, base_cols, progress=lambda n: progress(n),
                                   size_gr=gr, bounds={e.id: e.bounds(ctx) for e in effects if e.bounds},
                                   replication=options.replication, folds=options.replication_folds)
    progress.fill_to(selection_end)

    # final model on all training data
    final_cols = sel["columns"]
    theta_final = scoring.solve(gr_w, final_cols, np.arange(design_w.n_blocks))  # every whitened (1 s) block
    pos_of = {c: k for k, c in enumerate(final_cols)}

    entries = []
    esc_entry = {"id": ESC_DELAY, "explained_fraction": evidence["explained_fraction"], "ci": evidence["ci"],
                 **({"held_out_p_value": evidence["p_value"],
                     "held_out_weighted_fraction": evidence["held_out_weighted_fraction"]} if whitened else {}),
                 "axes": ["roll", "pitch", "yaw"], "params": {"delay_s": align["delay_s"],
                            **({"per_log_delay_s": align["per_log_delay_s"]} if "per_log_delay_s" in align else {})},
                 "significant": delay_significant}
    entries.append(esc_entry)
    for s in sel["selected"] + sel["others"]:
        cols = design.groups[s["id"]]
        if s["significant"]:
            th = np.array([theta_final[pos_of[c]] for c in cols])
        else:
            cols_all = final_cols + cols
            th_all = scoring.solve(gr_w, cols_all, np.arange(design_w.n_blocks))
            th = th_all[len(final_cols):]
        entries.append({"id": s["id"], "explained_fraction": s["explained_fraction"], "ci": s["ci"],
                        "axes": s["axes"], "params": _physical(design, th, s["id"], ctx),
                        "effect_size": s["effect_size"], "per_axis": s["per_axis"],
                        "explained_fraction_all_axes": s["explained_fraction_all_axes"],
                        **({"implausible": s["implausible"]} if "implausible" in s else {}),
                        "p_value": s["p_value"], "effect_test": s["effect_test"],
                        "held_out_p_value": s["held_out_p_value"],
                        "held_out_weighted_fraction": s["held_out_weighted_fraction"],
                        "physical_sign": s["physical_sign"],
                        "significant": s["significant"], **({"step": s["step"]} if "step" in s else {}),
                        **({"conditioned_on": s["conditioned_on"]} if "conditioned_on" in s else {}),
                        **({"dropped": s["dropped"]} if "dropped" in s else {})})
    loop_entry = closed_loop_entry(work_held or work, band_rule, requested_band, vehicle, kf_rotor, km_rotor,
                                   fit_blocks=sum(len(f.blocks) for f in work))
    if loop_entry is not None:
        entries.append(loop_entry)
    if delay_significant:  # the alignment is applied before any effect is scored: it ranks by its own share
        first = next((e for e in entries if e.get("step") == 1), None)
        esc_entry["step"] = 0 if first is None or esc_entry["explained_fraction"] >= first.get(
            "explained_fraction_all_axes", first["explained_fraction"]) else 1.5
    entries.sort(key=lambda e: (not e["significant"], e.get("step", 99),
                                -e.get("explained_fraction_all_axes", e["explained_fraction"])))
    significant = [e["id"] for e in entries if e["significant"]]
    verdict = significant[0] if significant else "none"
    for e in untestable:
        pass

    result = {
        "verdict": verdict,
        "significant": significant,
        "effects": entries,
        "untestable": untestable,
        "ambiguous": [{"candidates": a["candidates"], "kept": a["kept"], "reason": a["reason"],
                       "score_difference_ci": a["score_difference_ci"]} for a in sel["ambiguous"]],
        "inputs": {"logs": [str(l.path) for l in logs], "holdout": [str(l.path) for l in holdout],
                   "log_order": "canonical, whatever the command line's: sorted by a digest of each log's content "
                                "(gap/log_order.py); with 3 or more logs each log is a cross-validation fold of "
                                "its own (leave one log out), else the 1 s blocks form 5 folds (inputs.block_folds: "
                                "'first-row' numbers them across the logs in this order, 'phases' within each log)",
                   "block_folds": options.block_folds,
                   "landed_height_m": {f.name: f.landed_height for f in flights + held_flights},
                   "vehicle": str(vehicle.path) if vehicle.path else vehicle.name, "columns_present": present,
                   "band_hz": [options.band.highpass_hz, options.band.lowpass_hz],
                   "highpass_rule": None if band_rule is None else
                   {k: v for k, v in band_rule.items() if k != "ratio_boot"},
                   "rows": int(sum(f.rows for f in flights)), "blocks": int(design.n_blocks),
                   "rate_hz": [f.rate_hz for f in flights],
                   "inertia": ("unit: the vehicle file has no inertia, so torque coefficients (kf_roll, kf_pitch, "
                               "km_yaw, rotor_inertia, damping) are divided by the axis inertia [1/(kg m^2)]"
                               if unit_inertia else "vehicle file")},
        "gyro_bias": {"mode": options.gyro_bias,
                      "per_log": {str(f.path or f.name): f.gyro_bias for f in [*flights, *held_flights]}},
        "stream_quality": stream_quality(flights, held_flights, options.repeats),
        "alignment": {**{k: v for k, v in align.items() if k not in ("held_zero", "held_best")},
                      "nuisance": options.lag_nuisance},
        "base_model": {"kf_per_rotor": kf_rotor.tolist(), "km_per_rotor": km_rotor.tolist(),
                       "axis_sigma": dict(zip(design.axes, (1 / np.sqrt(gr.weight)).tolist()))},
    }
    progress(5)

    # base fit before / after
    shape = {"kf": (kf_rotor / np.mean(kf_rotor)).tolist() if np.mean(kf_rotor) > 0 else None,
             "km": (km_rotor / np.mean(km_rotor)).tolist() if np.mean(km_rotor) > 0 else None}
    if shape["kf"] is None or shape["km"] is None or min(shape["kf"] + shape["km"]) <= 0:
        shape = None  # a non-physical per-rotor split: plain fleet regressors
    # before: the requested band; a significant closed-loop cancellation is "in" after: the
    # band above the loop's bandwidth (the other effects are fitted there anyway)
    loop_in = CLOSED_LOOP in significant
    before_work = [replace(f, band=requested_band.for_rate(f.rate_hz)) for f in work] if loop_in else work
    base_shape, base_details = basefit.base_fit(before_work, vehicle.positions, vehicle.yaw_signs, vehicle.mass,
                                                shape=shape)
    extras, scales = {}, {}
    selected_ids = [e for e in significant if e not in (ESC_DELAY, CLOSED_LOOP)]
    by_entry = {e["id"]: e for e in entries}
    for eid in selected_ids:
        if eid == "inertia_error":
            scales["roll"] = by_entry[eid]["params"]["inertia_scale_xx"]
            scales["pitch"] = by_entry[eid]["params"]["inertia_scale_yy"]
        elif eid == "gyro_scale":
            m = by_entry[eid]["params"]["scale"]
            scales["roll"], scales["pitch"] = 1.0 / m[0], 1.0 / m[1]
        else:
            for axis in by_id(eid).axes:
                per_flight = [by_id(eid).build(f, ctx).get(axis) for f in work]
                extras.setdefault(axis, [None] * len(work))
                extras[axis] = [c if old is None else (old if c is None else np.column_stack([old, c]))
                                for old, c in zip(extras[axis], per_flight)]
    after_shape, after_details = basefit.base_fit(work, vehicle.positions, vehicle.yaw_signs, vehicle.mass,
                                                  extras, scales, shape=shape)
    instrument_scales = basefit.instrument_scales(scales, after_details)
    if instrument_scales:  # the torque scale without the attenuation the instrument removes
        scales = {axis: s["scale"] for axis, s in instrument_scales.items()}
        after_shape, after_details = basefit.base_fit(work, vehicle.positions, vehicle.yaw_signs, vehicle.mass,
                                                      extras, scales, shape=shape)
        if "inertia_error" in by_entry:
            params = by_entry["inertia_error"]["params"]
            for axis, key in (("roll", "inertia_scale_xx"), ("pitch", "inertia_scale_yy")):
                if axis in instrument_scales and "inertia_error" in selected_ids:
                    params[key + "_least_squares"] = params[key]
                    params[key] = instrument_scales[axis]["scale"]
    # the torque gain per band over the requested band (the closed loop's signature: basefit.torque_gain_per_band)
    gain_per_band = basefit.torque_gain_per_band(
        [replace(f, band=requested_band.for_rate(f.rate_hz)) for f in work], vehicle.positions, vehicle.yaw_signs,
        vehicle.mass, shape, (after_shape.get("kf_thrust") or {}).get("value"))
    roll_fit = base_details.get("kf_roll") or {}
    result["base_fit_method"] = (
        "torque coefficients by instrumental variables: the motor commands (cmd_i) predict the rotor speeds"
        if roll_fit.get("method", "").startswith("instrumental") else
        "torque coefficients by least squares: the logs have no motor commands (cmd_i) to use as instruments, "
        "so rotor-speed noise attenuates them (a lower bound)")
    result["base_fit"] = base_shape
    result["base_fit_after"] = after_shape
    result["base_fit_details"] = {"before": base_details, "after": after_details,
                                  **({"torque_scale_instrument": instrument_scales} if instrument_scales else {}),
                                  "agreement_before": _agreement(base_shape),
                                  "agreement_after": _agreement(after_shape),
                                  "torque_gain_per_band": gain_per_band,
                                  "thrust_offset": _thrust_offset_summary(options.band, base_details, after_details)}
    progress(10)

    # where (base model, held-out residual)
    base_res = scoring.cv_residuals(design, gr, base_cols)
    final_res = scoring.cv_residuals(design, gr, final_cols)
    per_axis, per_regime = where.per_axis_regime(design, base_res, vehicle.rotor_radius)
    theta_base_all = scoring.solve(gr, base_cols, np.arange(design.n_blocks))
    eiv = where.errors_in_variables(gr, base_cols, theta_base_all,
                                    [design.axes.index(a) for a in ("roll", "pitch")])
    if eiv.get("flag"):
        scale_like = [e for e in significant if e in SCALE_LIKE]
        if scale_like:
            result["ambiguous"].append({
                "candidates": scale_like + ["errors_in_variables"], "kept": scale_like[0],
                "reason": "the roll/pitch gain grows with excitation (where.errors_in_variables): noise on the "
                          "rotor-speed regressor attenuates every torque fit, which a torque scale also fits",
                "score_difference_ci": None})
    result["where"] = {"per_axis": per_axis, "per_regime": per_regime, "errors_in_variables": eiv,
                       "per_band": where.per_band(work, vehicle.positions, vehicle.yaw_signs, kf_rotor, km_rotor,
                                                  vehicle.mass),
                       "per_rotor": where.per_rotor(kf_rotor, km_rotor),
                       "thrust_gain_per_band": where.thrust_gain_per_band(work, vehicle.mass) if with_thrust else None}
    progress(5)

    # how far
    inertia = np.asarray(vehicle.inertia, dtype=float)
    if work_held:
        hd = build_design(work_held, ctx, effects + nuisances, vehicle.mass, with_thrust, scale=design.scale)
        theta_base = scoring.solve(gr, base_cols, np.arange(design.n_blocks))
        before = scoring.residuals(hd, base_cols, theta_base)
        after = scoring.residuals(hd, final_cols, theta_final)
        gr_hd = scoring.grams(hd)
        gr_hd.weight = gr.weight
        library = scoring.residuals(hd, all_cols, scoring.solve(gr_hd, all_cols, np.arange(hd.n_blocks)))
        result["shrink"] = shrink.shrink_table(hd, before, after, inertia, vehicle.mass, library)
        result["shrink_on"] = "hold-out logs"
        if options.explainable:  # how much of that residual any linear model of the logged signals predicts
            bound = explainable.heldout_bound(work, scoring.residuals(design, base_cols, theta_base), work_held,
                                              before)
            noise = explainable.gyro_noise_floor(work_held, inertia, before)
    else:
        # full_residual: base + every testable candidate, in-sample on these rows (the floor)
        result["shrink"] = shrink.shrink_table(design, base_res, final_res, inertia, vehicle.mass, full_residual)
        result["shrink_on"] = "cross-validation held-out blocks" if len(flights) < 3 else "cross-validation held-out flights"
        if options.explainable:
            all_blocks = np.arange(design.n_blocks)

            def base_residual_without(k):
                train = all_blocks[gr.fold != k]
                theta = scoring.solve(gr, base_cols, train if train.size else all_blocks)
                return scoring.residuals(design, base_cols, theta)

            bound = explainable.out_of_fold(work, sorted(np.unique(gr.fold).tolist()), gr.fold[design.block],
                                            base_residual_without)
            noise = explainable.gyro_noise_floor(work, inertia, base_res)
    if options.explainable:
        result["explainable"] = explainable.summary(bound, noise, result["shrink"])
    # what bounds the shrink: the torque no linear model of the logged input channels predicts
    result["shrink_bound"] = coherence.shrink_bound(work_held or work, result["shrink"])
    corrected, carried = corrected_vehicle(original_vehicle, entries)
    result["vehicle_out"] = carried
    result["_internal"] = {"corrected": corrected, "design": design, "base_res": base_res, "final_res": final_res,
                           "progress": progress}
    return result


REPEATED_ROWS_NOTABLE = 0.05  # above this share of a stream's rows the report names the copies


def stream_quality(flights: list[Flight], held: list[Flight], repeats: str) -> dict:
    """Per log and stream, the rows that repeat the previous row bit for bit (a logger's copies of
    lost packets, prep.repeated_rows) among the flying rows analysed, and how they were treated."""
    per_log = {f.name: {"gyro": f.repeated_rows["gyro"], "rotor": f.repeated_rows["rotor"],
                        "role": "fit" if k < len(flights) else "holdout"}
               for k, f in enumerate(flights + held)}
    notable = sorted(name for name, v in per_log.items()
                     if max(v["gyro"]["share"], v["rotor"]["share"]) > REPEATED_ROWS_NOTABLE)
    return {"repeated_rows": {
        "treated_as": repeats, "per_log": per_log, "logs_above_5_percent": notable,
        "rule": "a row whose gyro triple (rotor speeds) equals the previous row's bit for bit is a copy of a lost "
                "packet, not a sample (all-zero rotor rows excepted); treated_as: how the fits took them "
                "('samples' as measurements, the default; 'missing': torque and Omega^2 interpolated across the "
                "rows they leave unmeasured); the firmware-filter check skips them (--skip-repeats) either way"}}


def _thrust_offset_summary(band: Band, before: dict, after: dict) -> dict:
    """OUT.json base_fit_details.thrust_offset: the thrust axis's constant per log (basefit.thrust_offsets)."""
    if not band.thrust_offset:
        return {"mode": "none", "note": "the thrust axis is fitted through the origin: an accelerometer z offset "
                                        "b_z scales kf_thrust by 1 + b_z/g"}
    fit_before, fit_after = before.get("kf_thrust") or {}, after.get("kf_thrust") or {}
    if "thrust_offset" not in fit_before:
        return {"mode": "segment", "note": "no thrust axis (accelerometer or mass missing)"}
    return {"mode": "segment", "units": "m/s^2 (the accelerometer's z offset)",
            "before": fit_before["thrust_offset"], "after": fit_after.get("thrust_offset")}


def closed_loop_entry(flights: list[Flight], band_rule: dict | None, requested: Band, vehicle: Vehicle,
                      kf: np.ndarray, km: np.ndarray, fit_blocks: int) -> dict | None:
    """The controller cancelling a slow unmodelled torque with its rotors: the rotors then
    carry a torque the gyro never sees, so a torque fit over a band reaching down to it
    reads low (closed-loop identification bias). Its signature is the band rule's: the
    roll/pitch kf rises with the band's lower edge. Significant when the rule gave up the
    requested lower edge (the kf there shown more than BAND_STABILITY below the chosen
    band's) on at least MIN_CANCELLATION_BLOCKS fitted blocks. Physical parameters: the band edge above which the fits agree (the loop's
    disturbance-rejection bandwidth, to the candidates' resolution), the torque gain of
    the requested band against it, and the rms of the roll/pitch torque the base model
    (fitted above the loop) leaves below that edge: the disturbance torque the controller
    cancels. explained_fraction: the share of the base model's roll/pitch residual power
    (lowest candidate edge to the low-pass; held-out logs when given) that lies below the
    chosen edge, with a 95 % block-bootstrap interval."""
    if band_rule is None:
        return None
    chosen = band_rule["chosen_hz"]
    cands = band_rule["candidates_hz"]
    req = requested.highpass_hz
    ref = min(cands, key=lambda h: abs(h - req))
    ratio = np.asarray(band_rule["ratio_boot"][ref], dtype=float)
    ratio = ratio[np.isfinite(ratio)]
    gain = band_rule["roll_pitch_kf"][cands.index(ref)] / band_rule["roll_pitch_kf"][cands.index(chosen)] \
        if band_rule["roll_pitch_kf"][cands.index(chosen)] else float("nan")
    theta = np.concatenate([kf, km])
    lowest = cands[0]
    below, total = [], []  # per 2 s block: residual power below the edge, over the whole band
    rms_sq, rows = 0.0, 0
    for f in flights:
        cols = base_columns(f, vehicle.positions, vehicle.yaw_signs)
        resp = responses(f, vehicle.mass)
        top = f.band.lowpass_hz
        for a in ("roll", "pitch"):
            res = resp[a] - difference_response(cols[a] @ theta, f.rate_hz)
            for s0, e0 in f.segs:
                lo_part = bandpass(res[s0:e0, None], f.rate_hz, lowest, chosen)[:, 0] if chosen > lowest \
                    else np.zeros(e0 - s0)
                whole = bandpass(res[s0:e0, None], f.rate_hz, lowest, top)[:, 0]
                rms_sq += float(np.sum(lo_part**2))
                rows += e0 - s0
                for b0, b1 in f.blocks:
                    if s0 <= b0 < e0:
                        below.append(float(np.sum(lo_part[b0 - s0:b1 - s0] ** 2)))
                        total.append(float(np.sum(whole[b0 - s0:b1 - s0] ** 2)))
    below, total = np.asarray(below), np.asarray(total)
    frac = float(below.sum() / total.sum()) if total.sum() > 0 else float("nan")
    rng = np.random.default_rng(11)
    boot = []
    for _ in range(scoring.BOOTSTRAP):
        pick = rng.integers(0, len(total), len(total)) if len(total) else np.zeros(0, dtype=int)
        t = total[pick].sum()
        boot.append(below[pick].sum() / t if t > 0 else np.nan)
    boot = np.asarray(boot)
    boot = boot[np.isfinite(boot)]
    ci = [float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))] if boot.size else [float("nan")] * 2
    # the chosen band's kf must be shown > 0 for the ratio to it to be bounded (Fieller)
    chosen_positive = band_rule.get("kf_shown_positive", [True] * len(cands))[cands.index(chosen)]
    significant = bool(chosen > req and ratio.size and fit_blocks >= MIN_CANCELLATION_BLOCKS and chosen_positive
                       and np.percentile(ratio, 97.5) < 1.0 - BAND_STABILITY)
    return {"id": CLOSED_LOOP, "explained_fraction": frac, "ci": ci, "axes": ["roll", "pitch"],
            "params": {"loop_bandwidth_hz": chosen,
                       # the highest candidate: the kf may still rise above it (a lower bound)
                       "loop_bandwidth_at_least": bool(chosen == cands[-1] and chosen > cands[0]),
                       "torque_gain_below": float(gain),
                       "torque_gain_below_ci": ([float(np.percentile(ratio, 2.5)), float(np.percentile(ratio, 97.5))]
                                                if ratio.size else [float("nan")] * 2),
                       "requested_highpass_hz": req,
                       "disturbance_torque_rms": float(np.sqrt(rms_sq / rows)) if rows else float("nan")},
            "significant": significant,
            "evidence": "the roll/pitch torque kf of the band from the requested edge against the band above "
                        "the chosen edge (highpass_rule); the base model, coefficients and every other effect "
                        "are scored above the chosen edge"}


def _agreement(shape: dict) -> dict:
    thrust = shape.get("kf_thrust")
    if not thrust:
        return {}
    out = {}
    for key in ("kf_roll", "kf_pitch"):
        if shape.get(key):
            out[key + "_over_thrust"] = shape[key]["value"] / thrust["value"]
    return out
