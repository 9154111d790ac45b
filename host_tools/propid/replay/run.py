"""Run a flight log through the C filter, sample by sample at the log's own times."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from propid import cfilter
from propid.cfilter import DEFAULT_TUNING
from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.km_evidence import combination_std
from propid.replay.alignment import detect_streams, estimate_esc_delay, filter_input_rule, gyro_rows_with_mask
from propid.replay.averaging import MEAN_ESTIMATORS, MEAN_WINDOWS, coefficient_means, window_start
from propid.replay.config import build_config
from propid.replay.instrument import resolve_instrument
from propid.replay.noise import nis_mean, replay_nis
from propid.replay.options import US, ReplayOptions, ReplayResult
from propid.replay.prefilter import highpass_emulation_log, prefilter_log
from propid.replay.report_timing import resolve_rotor_timing_error
from propid.replay.rotor_spread import spread_bound
from propid.replay.session import FilterSession, segment_mask
from propid.replay.start import STARTS, flying_start
from propid.replay.thrust_aero import carry_thrust_aero
from propid.replay.vehicle_terms import undo_gyro_scale
from propid.signals import median_dt, repeats_previous_row


COMMAND_PUSH, ROTOR_PUSH = 0, 1


def input_pushes(rows: np.ndarray, streams: str, logged_streams: str, has_rotor: np.ndarray,
                 commands: np.ndarray | None, t_us: np.ndarray) -> list[tuple[int, int]]:
    """The filter's input pushes in order, (COMMAND_PUSH or ROTOR_PUSH, row): a row's command before its
    rotor speeds. A log written as rows pushes its commands with its rotor rows (each row's command, then
    its speeds). A log written as events may carry the commands on other rows (on the gyro rows, or on
    rows of their own): each finite command is pushed at its own stamp, before the rotor speeds of an
    equal stamp, as the rows copy of the same samples pushes them."""
    has_command = (np.all(np.isfinite(commands), axis=1) if commands is not None
                   else np.zeros(has_rotor.shape, dtype=bool))
    if logged_streams == "rows":
        pushes = []
        for j in rows:
            if streams == "rows" or has_rotor[j]:
                if has_command[j]:
                    pushes.append((COMMAND_PUSH, int(j)))
                pushes.append((ROTOR_PUSH, int(j)))
        return pushes
    keyed = [(int(t_us[j]), COMMAND_PUSH, int(j)) for j in rows if has_command[j]]
    keyed += [(int(t_us[j]), ROTOR_PUSH, int(j)) for j in rows if has_rotor[j]]
    keyed.sort()
    return [(kind, j) for _, kind, j in keyed]


def replay(log: FlightLog, vehicle: Vehicle, options: ReplayOptions | None = None) -> ReplayResult:
    """Run the log through the C filter; return the summary (JSON-ready) and time series."""
    options = options or ReplayOptions()
    if options.mean_window not in MEAN_WINDOWS:
        raise UserError(f"mean window {options.mean_window!r}: one of {', '.join(MEAN_WINDOWS)}")
    if options.mean_estimator not in MEAN_ESTIMATORS:
        raise UserError(f"mean estimator {options.mean_estimator!r}: one of {', '.join(MEAN_ESTIMATORS)}")
    if options.start not in STARTS:
        raise UserError(f"--start {options.start!r}: choose {' or '.join(STARTS)}")
    if log.rotor_count != vehicle.rotor_count:
        raise UserError(f"the log has {log.rotor_count} rotors, the vehicle file {vehicle.rotor_count}")
    log, gyro_scale_note = undo_gyro_scale(log, vehicle, options)  # the boundary: true rates from here on
    log, thrust_aero_note = carry_thrust_aero(log, vehicle, options.thrust_aero)  # and the filter's thrust row
    if options.noise == "nis":
        result = replay_nis(log, vehicle, replace(options, gyro_scale="off", thrust_aero="off"))  # both done above
        result.summary["config_notes"]["thrust_aero"] = thrust_aero_note
        return result
    streams = detect_streams(log) if options.streams == "auto" else options.streams
    logged_streams = streams  # --skip-repeats turns a rows log into events below; the time base stays the rows'
    mask = segment_mask(log, options.segment)
    rows = np.flatnonzero(mask)
    if rows.size == 0:
        raise UserError("no rows to replay (is the vehicle ever flying? try --segment all)")
    if not np.isfinite(log.gyro[rows]).any():
        raise UserError("no finite gyro sample in the rows to replay (gyro columns empty or NaN): nothing to "
                        "estimate from")
    if not np.isfinite(log.rotor_speed[rows]).any():
        raise UserError("no finite rotor speed in the rows to replay (omega columns empty or NaN): the filter "
                        "has no input")
    rates = stream_rates(log, rows)
    prefilter_info = None
    if options.prefilter_hz is not None:
        if streams != "rows" or options.skip_repeats:
            raise UserError("the matched pre-filter needs a rows log (one gyro and one rotor sample per row, uniform "
                            "time) and cannot be combined with --skip-repeats")
        inertia = np.eye(3) if options.unit_inertia or vehicle.inertia is None else np.asarray(vehicle.inertia)
        log, prefilter_info = prefilter_log(log, vehicle, mask, options.prefilter_hz, inertia)
    highpass_info = None
    if options.diagnostic_highpass_hz is not None:
        if streams != "rows" or options.skip_repeats:
            raise UserError("--diagnostic-highpass needs a rows log and cannot be combined with --skip-repeats")
        log, highpass_info = highpass_emulation_log(log, vehicle, mask, float(options.diagnostic_highpass_hz))
    config_fields, notes = build_config(vehicle, log, options)
    notes["gyro_scale"] = gyro_scale_note
    notes["thrust_aero"] = thrust_aero_note
    if options.thrust_aero == "on" and notes.get("aiding") != "gyro+accel":
        raise UserError("--thrust-aero on corrects the accelerometer: it needs --aiding gyro+accel")
    esc_delay_s, delay_rule = resolve_esc_delay(log, vehicle, mask, options, logged_streams)
    delay_us = int(round(esc_delay_s * US))
    config_fields["rotor_delay_us"] = delay_us  # the firmware holds the leading stream (docs/math.md §12)
    resolve_scale_walk(log, vehicle, mask, options, config_fields, notes, esc_delay_s)
    resolve_thrust_coeff_walk(log, vehicle, mask, options, config_fields, notes, esc_delay_s)
    resolve_rotor_speed_noise(log, mask, options, config_fields, notes)
    resolve_rotor_timing_error(log, mask, options.rotor_timing_error, config_fields, notes)
    if prefilter_info is not None:
        notes["prefilter"] = prefilter_info
    if highpass_info is not None:
        notes["diagnostic_highpass"] = highpass_info
    commands = resolve_instrument(log, mask, options, config_fields, notes)
    filt = FilterSession(vehicle, config_fields)
    kf_nominal = [float(v) for v in config_fields["thrust_coeff_nominal"]]
    km_nominal = [float(v) for v in config_fields["drag_coeff_nominal"]]
    converged_rel_std = float(config_fields.get("converged_rel_std", DEFAULT_TUNING["converged_rel_std"]))
    t_us = np.round((log.t - log.t[0]) * US).astype(np.int64) + US  # start at 1 s: time 0 is 'no time yet'
    speeds = np.ascontiguousarray(log.rotor_speed, dtype=np.float32)
    aiding = notes.get("aiding", "gyro")
    acc = np.ascontiguousarray(log.acc, dtype=np.float32) if aiding == "gyro+accel" else None
    has_acc = np.all(np.isfinite(acc), axis=1) if acc is not None else None
    gyro = np.ascontiguousarray(log.gyro, dtype=np.float32)
    has_gyro = np.any(np.isfinite(log.gyro), axis=1)
    has_rotor = np.any(np.isfinite(log.rotor_speed), axis=1)
    repeats = {"gyro": 0, "rotor": 0, "accel": 0}
    if options.skip_repeats:
        same_gyro, same_rotor = repeats_previous_row(log.gyro), repeats_previous_row(log.rotor_speed)
        repeats = {"gyro": int(np.sum(same_gyro[mask])), "rotor": int(np.sum(same_rotor[mask])), "accel": 0}
        has_gyro &= ~same_gyro
        has_rotor &= ~same_rotor
        if has_acc is not None:
            # the accelerometer is a stream of its own: its copy is no sample either (its fresh sample on a
            # row whose gyro repeats is one, pushed at its own time below)
            same_acc = repeats_previous_row(log.acc)
            repeats["accel"] = int(np.sum(same_acc[mask]))
            has_acc &= ~same_acc
        if streams == "rows":
            streams = "events"  # rows now carry one stream or the other
    status_counts: dict[str, int] = {}
    n = vehicle.rotor_count
    rec_t, rec_kf, rec_kfs, rec_km, rec_kms, rec_bg, rec_bgs, rec_conv_kf, rec_conv_km, rec_nis, rec_rate = (
        [] for _ in range(11))
    rec_scale = []
    rec_mean_std = []  # the rotor mean kf's relative std (options.rotor_mean_std_every), NaN between
    gate = float(config_fields.get("gate_sigma", DEFAULT_TUNING["gate_sigma"]))
    resyncs = 0
    gyro_pushes = 0
    gyro_accepted = 0
    # The filter's rows: the segment's, from the start the rule gives (the per-log rules above measured on
    # the whole segment).
    start_row = flying_start(log) if options.start == "flying" else 0
    filter_rows = rows[rows >= start_row]
    if filter_rows.size == 0:
        filter_rows, start_row = rows, 0
    iterator = filter_rows
    if options.progress:
        from tqdm import tqdm

        iterator = tqdm(filter_rows, desc="replay", unit="row", mininterval=0.5, leave=False)
    # Every sample at its logged time, the streams interleaved in time order (commands, then rotor
    # speeds, then the gyro at equal stamps); the filter realigns them by its configured delay.
    inputs = input_pushes(filter_rows, streams, logged_streams, has_rotor, commands, t_us)
    next_input = 0
    for i in iterator:
        while next_input < len(inputs) and t_us[inputs[next_input][1]] <= t_us[i]:
            kind, j = inputs[next_input]
            next_input += 1
            if kind == COMMAND_PUSH:
                # The lag holds the previous command up to this stamp.
                status = filt.push_motor_command(int(t_us[j]), commands[j])
                if status < 0:
                    name = "command " + filt.status_name(status)
                    status_counts[name] = status_counts.get(name, 0) + 1
                continue
            status = filt.push_rotor_speeds(int(t_us[j]), speeds[j])
            if status < 0:
                name = filt.status_name(status)
                status_counts[name] = status_counts.get(name, 0) + 1
        if streams == "rows" or has_gyro[i]:
            status = filt.push_gyro(int(t_us[i]), gyro[i])
            if status == filt.TIME_JUMP:
                filt.resync(int(t_us[i]))
                resyncs += 1
                status = filt.push_gyro(int(t_us[i]), gyro[i])
            if status < 0:
                name = filt.status_name(status)
                status_counts[name] = status_counts.get(name, 0) + 1
            else:
                gyro_accepted += 1
            gyro_pushes += 1
            if has_acc is not None and has_acc[i]:
                status = filt.push_accel(int(t_us[i]), acc[i])
                if status < 0:
                    name = "accel " + filt.status_name(status)
                    status_counts[name] = status_counts.get(name, 0) + 1
            if gyro_pushes % options.record_every == 0:
                est = filt.estimate()
                rec_t.append(log.t[i])
                rec_kf.append(est["thrust_coeff"][:n])
                rec_kfs.append(est["thrust_coeff_std"][:n])
                rec_km.append(est["drag_coeff"][:n])
                rec_kms.append(est["drag_coeff_std"][:n])
                rec_bg.append(est["gyro_bias"])
                rec_bgs.append(est["gyro_bias_std"])
                rec_rate.append(est["body_rate"])
                rec_scale.append(est["torque_scale"])
                if options.rotor_mean_std_every > 0 and (len(rec_t) - 1) % options.rotor_mean_std_every == 0:
                    rec_mean_std.append(rotor_mean_rel_std(filt.thrust_coeff_covariance(), est["thrust_coeff"][:n]))
                else:
                    rec_mean_std.append(np.nan)
                # The averaging window starts where the relative std first falls below
                # converged_rel_std (one std: the estimate has settled), whatever the
                # filter's claim says (that asks 3 std and the consistency monitor's
                # vouching, docs/reliability.md; the estimate is the same).
                rec_conv_kf.append([est["thrust_coeff_std"][k] < converged_rel_std * kf_nominal[k] for k in range(n)])
                rec_conv_km.append([est["drag_coeff_std"][k] < converged_rel_std * km_nominal[k] for k in range(n)])
                rec_nis.append(est["innovation_test_ratio"] if status >= 0 else [np.nan] * 3)
        elif has_acc is not None and has_acc[i]:
            # an accelerometer row of its own (events log): at its own time, as the gyro
            status = filt.push_accel(int(t_us[i]), acc[i])
            if status < 0:
                name = "accel " + filt.status_name(status)
                status_counts[name] = status_counts.get(name, 0) + 1
    if not rec_t:
        raise UserError("no gyro sample was replayed")
    if gyro_accepted == 0:
        raise UserError(f"the filter accepted none of the {gyro_pushes} gyro samples (rejected: "
                        f"{dict(sorted(status_counts.items()))}): the estimates would be the prior")
    series = {
        "t": np.array(rec_t),
        "kf": np.array(rec_kf, dtype=float),
        "kf_std": np.array(rec_kfs, dtype=float),
        "km": np.array(rec_km, dtype=float),
        "km_std": np.array(rec_kms, dtype=float),
        "gyro_bias": np.array(rec_bg, dtype=float),
        "gyro_bias_std": np.array(rec_bgs, dtype=float),
        "body_rate": np.array(rec_rate, dtype=float),
        "torque_scale": np.array(rec_scale, dtype=float),
        "kf_rotor_mean_rel_std": np.array(rec_mean_std, dtype=float),
        "kf_converged": np.array(rec_conv_kf, dtype=bool),
        "km_converged": np.array(rec_conv_km, dtype=bool),
        "nis": np.array(rec_nis, dtype=float) * (gate * gate if gate > 0 else np.nan),
    }
    final = filt.estimate()
    counters = filt.counters()
    if delay_us != 0:
        # Held samples are fused (or rejected) after their push returned PROPID_OK_QUEUED: their
        # outcome is in the filter's counters only.
        status_counts = {name: int(count) for name, count in counters["rejected"].items()}
        gyro_accepted = int(counters["gyro_accepted"])

    window, estimator = options.mean_window, options.mean_estimator
    # The walks the filter ran with, in the estimates' units squared per second (the smoothed mean's model)
    kf_walk = float(config_fields.get("thrust_coeff_rel_walk", DEFAULT_TUNING["thrust_coeff_rel_walk"]))
    km_walk = float(config_fields.get("drag_coeff_rel_walk", DEFAULT_TUNING["drag_coeff_rel_walk"]))
    kf_means = coefficient_means(series["kf"], series["kf_std"], series["kf_converged"], series["t"],
                                 [(kf_walk * v) ** 2 for v in kf_nominal], estimator, window)
    km_means = coefficient_means(series["km"], series["km_std"], series["km_converged"], series["t"],
                                 [(km_walk * v) ** 2 for v in km_nominal], estimator, window)
    # The torque scale over the window every rotor's window mean covers: from the latest window start.
    scale_from = max(window_start(series["kf_converged"][:, k], window) for k in range(n))
    torque_scale_mean = float(np.mean(series["torque_scale"][scale_from:]))
    # The filter's own claim at the end (withdrawn while MODEL_MISMATCH is up).
    kf_conv = [bool((final["thrust_coeff_converged"] >> k) & 1) for k in range(n)]
    km_conv = [bool((final["drag_coeff_converged"] >> k) & 1) for k in range(n)]
    finite = estimates_finite(series)
    summary = {
        "log": str(log.path) if log.path else None,
        "vehicle": str(vehicle.path) if vehicle.path else vehicle.name,
        "mode": "unit_inertia" if options.unit_inertia else "si",
        "units": {
            "kf": "N/(rad/s)^2" if not options.unit_inertia else "kf/J: (rad/s^2)/(rad/s)^2 per metre of arm, J = 1 kg m^2",
            "km": "N m/(rad/s)^2" if not options.unit_inertia else "km/Jzz: (rad/s^2)/(rad/s)^2",
            "gyro_bias": "rad/s",
        },
        "segment": options.segment,
        "start": {"rule": options.start, "from_s": float(log.t[filter_rows[0]] - log.t[0]),
                  "rows_left_out": int(rows.size - filter_rows.size)},
        "streams": streams,
        "rows_replayed": int(filter_rows.size),
        "repeated_rows_skipped": repeats,
        "esc_delay_s": esc_delay_s,
        "esc_delay_rule": delay_rule,
        "rotor_delay_s": -esc_delay_s,  # the older convention: rotor speeds acting this much after their stamp
        "rotor_delay_rule": delay_rule,
        "filter_rotor_input": filter_input_rule(),
        "duration_s": float(log.t[filter_rows[-1]] - log.t[filter_rows[0]]),
        "gyro_rate_hz": rates["gyro"],
        "rotor_rate_hz": rates["rotor"],
        "gyro_samples_accepted": gyro_accepted,
        "gyro_samples_pushed": gyro_pushes,
        "kf": [float(v) for v in final["thrust_coeff"][:n]],
        "kf_std": [float(v) for v in final["thrust_coeff_std"][:n]],
        "km": [float(v) for v in final["drag_coeff"][:n]],
        "km_std": [float(v) for v in final["drag_coeff_std"][:n]],
        "kf_mean": kf_means["mean"],
        "km_mean": km_means["mean"],
        "mean_estimator": estimator,
        "kf_mean_window": kf_means["window"],
        "km_mean_window": km_means["window"],
        "kf_mean_inverse_variance": kf_means["inverse_variance"],
        "km_mean_inverse_variance": km_means["inverse_variance"],
        "kf_mean_smoothed": kf_means["smoothed"],
        "km_mean_smoothed": km_means["smoothed"],
        "kf_rotor_spread_bound": spread_bound(np.asarray(kf_means["mean"]), filt.thrust_coeff_covariance()),
        # Relative std of the km combination each input channel measures (km_evidence.py): yaw -> the mean km.
        "km_combination_std": combination_std(filt.drag_coeff_rel_covariance(), filt.vehicle),
        "kf_converged_from_s": kf_means["crossing"],
        "km_converged_from_s": km_means["crossing"],
        "kf_mean_from_s": kf_means["from"],
        "km_mean_from_s": km_means["from"],
        "mean_window": window,
        "converged": {"kf": kf_conv, "km": km_conv},
        "model_mismatch": bool(int(final["health"]) & cfilter.HEALTH["MODEL_MISMATCH"]),
        "model_mismatch_windows": int(counters.get("model_mismatch", 0)),
        "gyro_bias": [float(v) for v in final["gyro_bias"]],
        "gyro_bias_std": [float(v) for v in final["gyro_bias_std"]],
        "aiding": aiding,
        "disturbance": notes.get("disturbance", "off"),
        "rotor_inertia": notes.get("rotor_inertia", "not modelled"),
        "aero_damping": notes.get("aero_damping", "not modelled"),
        "gyro_scale": notes.get("gyro_scale", "none"),
        "disturbance_torque": [float(v) for v in final["disturbance_torque"]],
        "disturbance_torque_std": [float(v) for v in final["disturbance_torque_std"]],
        # None (JSON null) when no accelerometer was fused: there is no bias state to report.
        "accel_bias": float(final["accel_bias"]) if acc is not None else None,
        "accel_bias_std": float(final["accel_bias_std"]) if acc is not None else None,
        "torque_scale": float(final["torque_scale"]),
        "torque_scale_std": float(final["torque_scale_std"]),
        "torque_scale_mean": torque_scale_mean,
        "rejected": dict(sorted(status_counts.items())),
        "nis_mean": nis_mean(series),
        "counters": counters,
        "resyncs_by_replay": resyncs,
        "health": int(final["health"]),
        "finite": bool(finite),
        "body_rate_max_abs": float(np.max(np.abs(series["body_rate"]))) if finite else float("nan"),
        "config": config_fields,
        "config_notes": notes,
        "warnings": replay_warnings(rates, gyro_accepted, gyro_pushes,
                                    None if options.skip_repeats else repeated_gyro_share(log, filter_rows)),
        "definitions": {
            "kf_mean": "kf_mean_window, kf_mean_inverse_variance or kf_mean_smoothed, as mean_estimator says "
                       "(km_mean the same)",
            "kf_mean_window": "mean of the estimate from the first sample with rel std < converged_rel_std to the "
                              "end; second half of the replay if never below; mean_window at-least-half: from the "
                              "midpoint when that is earlier (replay/averaging.py)",
            "kf_mean_inverse_variance": "mean of every recorded estimate of the replay weighted by 1/std^2 "
                                        "(replay/averaging.py)",
            "kf_mean_smoothed": "time mean over the replay of the estimate smoothed backwards (each sample's "
                                "estimate given every sample, the coefficient a random walk with "
                                "thrust_coeff_rel_walk; km: drag_coeff_rel_walk) (replay/averaging.py)",
            "kf_mean_from_s": "log time the kf_mean_window window starts (km_mean_from_s: km_mean_window's)",
            "kf_converged_from_s": "log time kf's rel std first fell below converged_rel_std (null if never)",
            "kf_rotor_spread_bound": "each rotor's std of kf_i / mean(kf) - 1 from the final covariance, and the "
                                     "probability that every rotor is within the tolerance of the run mean if the "
                                     "rotors were equal (replay/rotor_spread.py)",
            "km_combination_std": "relative std of the km combination each input channel (yaw, collective, roll, "
                                  "pitch) measures, from the final covariance: yaw -> the mean km (km_evidence.py)",
            "finite": "every recorded kf, km, their stds, gyro bias and body rate is finite",
            "torque_scale_mean": "mean of the thrust-torque scale from the latest rotor's kf_mean_window start to "
                                 "the end; 1 without the scale state",
            "converged": "the filter's converged flag at the end of the replay (none while model_mismatch)",
            "model_mismatch": "MODEL_MISMATCH health flag at the end: the innovations or the coefficients' drift "
                              "were inconsistent with the filter's covariance (docs/reliability.md)",
            "gyro_rate_hz/rotor_rate_hz": "new samples per second of each stream over the replayed rows (a row "
                                          "repeating the previous value of a stream is no new sample)",
        },
    }
    return ReplayResult(summary=summary, series=series)



def resolve_esc_delay(log: FlightLog, vehicle: Vehicle, mask: np.ndarray, options: ReplayOptions,
                      streams: str) -> tuple[float, str]:
    """(esc_delay_s, how it was chosen): the delay the filter is configured with."""
    choice = options.esc_delay
    if choice is None:  # the older option: rotor speeds pushed rotor_delay_s late
        if options.rotor_delay_s == "auto":
            choice = "auto"
        else:
            return -float(options.rotor_delay_s), "given (rotor delay)"
    if choice == "default":
        choice = "vehicle" if vehicle.esc_delay_s is not None else "auto"
    if choice == "vehicle":
        value = float(vehicle.esc_delay_s or 0.0)
        return value, "vehicle file esc_delay_s" if vehicle.esc_delay_s is not None else "vehicle file: none (0)"
    if choice == "auto":
        if streams != "rows" and rotor_stream_is_slower(log, mask):
            return 0.0, ("auto: 0 for an events log whose rotor stream is slower than its gyro (the hold between "
                         "rotor samples is itself a lag that varies sample to sample; no whole-sample shift fits it)")
        # On an events log the rule reads the gyro rows with the rotor speeds in force at each: the input the
        # filter's hold gives the step, as on the rows copy of the same samples.
        rows, rows_mask = gyro_rows_with_mask(log, mask)
        return (estimate_esc_delay(rows, vehicle, rows_mask, unit_inertia=options.unit_inertia),
                "auto: whole-sample lag (-50..50 ms) maximising the 2-10 Hz R^2 of measured vs modelled "
                "roll/pitch torque in the filter's Euler step")
    return float(choice), "given"


def rotor_stream_is_slower(log: FlightLog, mask: np.ndarray) -> bool:
    """Fewer rows of `mask` log a rotor sample than log a gyro sample (by more than a tenth)."""
    logs_rotor = np.any(np.isfinite(log.rotor_speed[mask]), axis=1).sum()
    logs_gyro = np.any(np.isfinite(log.gyro[mask]), axis=1).sum()
    return bool(logs_rotor < 0.9 * logs_gyro)


def rotor_mean_rel_std(covariance: np.ndarray, kf) -> float:
    """The relative std of the rotors' mean kf, sqrt(1' C 1) / n / mean(kf), C the rotors' kf covariance: what the
    accelerometer pins (their sum), whatever the gyro knows of how the rotors differ."""
    kf = np.asarray(kf, dtype=float)
    mean = float(np.mean(kf))
    if not (mean > 0 and np.all(np.isfinite(covariance))):
        return float("inf")
    return float(np.sqrt(max(float(np.sum(covariance)), 0.0)) / kf.size / mean)


def estimates_finite(series: dict) -> bool:
    """Every recorded estimate and std the replay reports, the body rate included."""
    keys = ("kf", "kf_std", "km", "km_std", "gyro_bias", "gyro_bias_std", "body_rate")
    return all(np.all(np.isfinite(series[k])) for k in keys if k in series)


# Below these rates the filter's discretisation (one Euler step per gyro sample, rotor speed
# held between its samples) mis-states the torque of 2-10 Hz attitude motion: a held rotor
# sample acts on average half a sample late, i.e. 10 ms at 50 Hz, already 18 degrees of phase
# (5 % of in-phase torque) at 5 Hz; a gyro at 100 Hz makes 10 ms Euler steps. Estimates from
# slower logs are reported, with a warning, never silently as converged answers.
MIN_GYRO_RATE_HZ = 100.0
MIN_ROTOR_RATE_HZ = 50.0
MIN_ACCEPTED_GYRO_FRACTION = 0.5
# A row repeating the previous gyro triple bit for bit is a logger's copy of a lost packet; fused, it is a
# zero rate change against the rotor torque and kf reads low (10 % copies: 1-2 % low on the synthetic flight
# of docs/real-data.md "Repeated rows", 30 %: 5-11 %). Above this share the replay says so.
MAX_REPEATED_GYRO_SHARE = 0.05


def stream_rates(log: FlightLog, rows: np.ndarray) -> dict:
    """New samples per second of the gyro and the rotor-speed streams over `rows`: a row
    counts for a stream if it carries a finite value that differs from the stream's previous
    one (sample-and-hold resampling adds no information). The time is the time the rows
    cover: steps longer than 5 x the median step (skipped segments) do not count."""
    steps = np.diff(log.t[rows])
    positive = steps[steps > 0]
    duration = float(np.sum(steps[steps <= 5.0 * np.median(positive)])) if positive.size else 0.0

    def rate(values: np.ndarray) -> float:
        carried = values[rows]
        carried = carried[np.all(np.isfinite(carried), axis=1)]
        if carried.shape[0] < 2 or duration <= 0:
            return float("nan")
        new = 1 + int(np.sum(np.any(carried[1:] != carried[:-1], axis=1)))
        return new / duration

    return {"gyro": rate(log.gyro), "rotor": rate(log.rotor_speed)}


def repeated_gyro_share(log: FlightLog, rows: np.ndarray) -> float:
    """Share of the gyro samples among `rows` (indices) whose triple equals the previous gyro sample's, every
    axis finite (the log's first gyro sample has none before it; an events log's rotor rows are no gyro sample)."""
    logged = np.flatnonzero(np.any(np.isfinite(log.gyro), axis=1))
    rows = rows[np.isin(rows, logged[1:])]
    if rows.size == 0:
        return 0.0
    return float(np.sum(repeats_previous_row(log.gyro)[rows])) / rows.size


def replay_warnings(rates: dict, accepted: int, pushed: int, repeated_gyro: float | None = None) -> list[str]:
    warnings = []
    if rates["gyro"] < MIN_GYRO_RATE_HZ:
        warnings.append(f"gyro at {rates['gyro']:.0f} Hz (< {MIN_GYRO_RATE_HZ:.0f} Hz): the rate dynamics are "
                        "discretised too coarsely; kf/km are biased even when flagged converged")
    if rates["rotor"] < MIN_ROTOR_RATE_HZ:
        warnings.append(f"rotor speeds at {rates['rotor']:.0f} Hz (< {MIN_ROTOR_RATE_HZ:.0f} Hz): the held rotor "
                        "speed lags the true one; kf/km are biased even when flagged converged")
    if pushed and accepted < MIN_ACCEPTED_GYRO_FRACTION * pushed:
        warnings.append(f"the filter accepted only {accepted} of {pushed} gyro samples")
    if repeated_gyro is not None and repeated_gyro > MAX_REPEATED_GYRO_SHARE:
        warnings.append(f"{100 * repeated_gyro:.0f} % of the rows repeat the previous gyro sample (sample-and-hold "
                        "copies of lost packets, fused as measurements: kf reads low): replay with --skip-repeats")
    return warnings


def resolve_rotor_speed_noise(log: FlightLog, mask: np.ndarray, options: ReplayOptions, config_fields: dict,
                              notes: dict) -> None:
    """rotor_speed_noise(_time) from --rotor-speed-noise: a std, or auto (the per-log rule)."""
    noise = options.rotor_speed_noise
    time = options.rotor_speed_noise_time
    if time is not None and not (0.0 <= time <= 1.0):
        raise UserError(f"--rotor-speed-noise-time {time!r}: choose a number between 0 and 1 [s]")
    if noise is None:
        if time is not None:
            raise UserError("--rotor-speed-noise-time needs --rotor-speed-noise")
        if options.input_error_compensation:
            raise UserError("--input-error-compensation on needs --rotor-speed-noise (auto or a std): it removes the "
                            "part of the update an error of that size explains")
        return
    if noise == "auto":
        from propid.replay.input_noise import estimate_rotor_speed_noise

        info = estimate_rotor_speed_noise(log, mask)
        config_fields["rotor_speed_noise"] = info["sigma"]
        config_fields["rotor_speed_noise_time"] = info["time"] if time is None else time
        notes["rotor_speed_noise"] = info
    else:
        value = float(noise)
        if not (0.0 <= value <= 1.0e4):
            raise UserError(f"--rotor-speed-noise {noise!r}: choose auto or a number between 0 and 10000 [rad/s]")
        config_fields["rotor_speed_noise"] = value
        config_fields["rotor_speed_noise_time"] = 0.0 if time is None else time
        notes["rotor_speed_noise"] = "given"
    if options.input_error_compensation:
        # An error of size 0 (the rule found none) leaves nothing to compensate: the filter refuses the option then.
        on = config_fields["rotor_speed_noise"] > 0.0
        config_fields["input_error_compensation"] = int(on)
        notes["input_error_compensation"] = "on" if on else "requested, but the rotor-speed error is 0: off"


def resolve_thrust_coeff_walk(log: FlightLog, vehicle: Vehicle, mask: np.ndarray, options: ReplayOptions,
                              config_fields: dict, notes: dict, esc_delay_s: float) -> None:
    """thrust_coeff_rel_walk from --thrust-coeff-rel-walk auto: the library's walk and the per-log torque-gain
    walk q (replay/scale_walk.py) added in quadrature. Without the thrust-torque scale state the gyro sees the
    product scale x kf in the kf states, whose relative walk is that of the two independent walks together."""
    if options.thrust_coeff_walk is None:
        return
    if options.thrust_coeff_walk != "auto":
        raise UserError(f"thrust_coeff_walk {options.thrust_coeff_walk!r}: only 'auto' (a number goes through the "
                        "thrust_coeff_rel_walk override)")
    if "thrust_coeff_rel_walk" in options.overrides:
        raise UserError("--thrust-coeff-rel-walk: give a number or auto, not both")
    if config_fields.get("torque_scale"):
        raise UserError("--thrust-coeff-rel-walk auto is for the filter without the thrust-torque scale (that "
                        "state carries the changing gain: --torque-scale-walk auto)")
    from propid.replay.scale_walk import estimate_scale_walk

    rows, rows_mask = gyro_rows_with_mask(log, mask)  # the torque gain needs both streams on each row
    lag = int(round(-esc_delay_s / median_dt(rows.t)))
    info = estimate_scale_walk(rows, vehicle, rows_mask, lag, filter_input_rule() == "trapezoid")
    base = float(DEFAULT_TUNING["thrust_coeff_rel_walk"])
    walk = float(np.hypot(base, info["walk"]))
    config_fields["thrust_coeff_rel_walk"] = walk
    notes["thrust_coeff_rel_walk"] = dict(info, library_walk=base, torque_gain_walk=info["walk"], walk=walk,
                                          rule="sqrt(library walk^2 + torque-gain walk^2)")


def resolve_scale_walk(log: FlightLog, vehicle: Vehicle, mask: np.ndarray, options: ReplayOptions,
                       config_fields: dict, notes: dict, esc_delay_s: float) -> None:
    """torque_scale_walk from --torque-scale-walk: a number, or auto (the per-log rule)."""
    walk = options.torque_scale_walk
    if walk is None:
        return
    if not config_fields.get("torque_scale"):
        raise UserError("--torque-scale-walk needs the thrust-torque scale (--aiding gyro+accel, --torque-scale "
                        "auto or on)")
    if walk == "auto":
        from propid.replay.scale_walk import estimate_scale_walk

        rows, rows_mask = gyro_rows_with_mask(log, mask)  # the torque gain needs both streams on each row
        lag = int(round(-esc_delay_s / median_dt(rows.t)))
        info = estimate_scale_walk(rows, vehicle, rows_mask, lag, filter_input_rule() == "trapezoid")
        config_fields["torque_scale_walk"] = info["walk"]
        notes["torque_scale_walk"] = info
        return
    value = float(walk)
    if not (0.0 <= value <= 10.0):
        raise UserError(f"--torque-scale-walk {walk!r}: choose auto or a number between 0 and 10 [1/sqrt(s)]")
    config_fields["torque_scale_walk"] = value
    notes["torque_scale_walk"] = "given"
