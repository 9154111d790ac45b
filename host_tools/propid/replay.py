"""Replay a flight log through the firmware filter itself (C library via ctypes).

Both streams are pushed as recorded, at the log's own times:
- "rows" logs (one row = one gyro sample and one rotor sample, e.g. the SITL, the
  Crazyflie and Betaflight CSVs): every row pushes its rotor speeds, then its gyro. A
  row with a missing (NaN) or absurd rotor speed is pushed anyway and the filter
  rejects it (counted by reason); the filter keeps the previous rotor speeds.
- "events" logs (each stream on its own time base, as the ULog and tlog importers write
  them: gyro rows have empty omega_*, rotor rows have empty gyro_*): a row pushes only
  the stream it carries.
A gyro push answered with PROPID_ERR_TIME_JUMP (a gap, e.g. a cut-out segment) is
followed by propid_resync() at that time and pushed again.

Definitions used in the output (docs/real-data.md):
- converged part of a coefficient: from the first replayed gyro sample at which the
  filter reports it converged (relative std below config.converged_rel_std) to the end;
  kf_mean/km_mean average the estimate over it. A coefficient that never converges is
  averaged over the second half of the replayed samples and flagged converged = false.
- unit-inertia mode (vehicle without inertia, e.g. the Betaflight file): the filter
  runs with J = identity [kg m^2], so its "kf" is kf/J (roll/pitch; one J for both)
  and its "km" is km/Jzz, in the vehicle file's (possibly assumed) geometry. Ratios
  between rotors and changes over time are meaningful; absolute kf and km are not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.realdata_checks import absurd_speed_limit, check_log, flying_mask

US = 1_000_000


@dataclass
class ReplayOptions:
    segment: str = "all"  # "all" or "flying"
    streams: str = "auto"  # "auto", "rows" or "events"
    unit_inertia: bool = False
    kf_nominal: float | None = None  # override (unit-inertia mode: kf/J)
    km_nominal: float | None = None
    noise: str = "auto"  # "auto": from the log; "default": the library defaults
    max_rotor_speed: float | None = None  # None: 2x the 99.9th percentile of finite speeds
    overrides: dict = field(default_factory=dict)  # any other propid_config_t field
    skip_repeats: bool = False  # a row whose gyro (or rotor speeds) exactly repeat the previous row is no new sample
    rotor_delay_s: float | str = 0.0  # push rotor speeds this much later than logged, or "auto"
    prefilter_hz: float | str | None = None  # matched causal low-pass of gyro and rotor speed^2: Hz, "auto" or None
    diagnostic_highpass_hz: float | None = None  # diagnostic only: emulate removing slow content (docs/real-data.md)
    record_every: int = 1  # keep every k-th estimate for the time series
    progress: bool = True


@dataclass
class ReplayResult:
    summary: dict
    series: dict  # time series of the estimates (numpy arrays)


def detect_streams(log: FlightLog) -> str:
    """'events' if some rows carry rotor speeds but no gyro (separate time bases)."""
    gyro_missing = np.all(~np.isfinite(log.gyro), axis=1)
    rotor_missing = np.all(~np.isfinite(log.rotor_speed), axis=1)
    if np.any(gyro_missing & ~rotor_missing) and np.any(rotor_missing & ~gyro_missing):
        return "events"
    return "rows"


def estimate_noise(log: FlightLog, vehicle_inertia: np.ndarray, positions, signs, mask) -> dict:
    """Noise levels for the filter from the log itself (the 'auto' rule, docs/real-data.md).

    The filter models the body rate as driven by the rotor torques plus white angular
    acceleration noise q (rate_process_noise), seen through a gyro with white noise sigma.
    1. Fit per-rotor kf and km to the log by least squares with the filter's own torque
       model (so a wrong nominal does not count as 'unmodelled').
    2. Residual rate increments over k samples, r_k = w[n+k] - w[n] - sum(a_fit) dt, have
       variance q^2 k dt + 2 sigma^2: from k = 1 and k = K (about 50 ms) both follow.
    Only the log and the vehicle file's geometry and inertia enter; variances use the
    central 99 % of the increments (glitches out). Floors: sigma >= 1 mrad/s (below any
    MEMS gyro's noise or quantisation), q >= 1e-3 rad/s^2/sqrt(Hz)."""
    steps = np.diff(log.t)
    dt = float(np.median(steps[steps > 0]))
    gyro = log.gyro
    speeds = log.rotor_speed
    ok = mask.copy()
    ok &= np.all(np.isfinite(gyro), axis=1) & np.all(np.isfinite(speeds), axis=1)
    ok &= np.all(np.nan_to_num(speeds, nan=0.0) <= absurd_speed_limit(speeds), axis=1)
    inner = ok.copy()  # central differences need both neighbours
    inner[1:-1] &= ok[:-2] & ok[2:]
    inner[[0, -1]] = False
    if inner.sum() < 100:
        return {}
    rate_dot = np.zeros_like(gyro)
    rate_dot[1:-1] = (gyro[2:] - gyro[:-2]) / (log.t[2:] - log.t[:-2])[:, None]
    torque = rate_dot @ vehicle_inertia.T + np.cross(gyro, gyro @ vehicle_inertia.T)
    u = np.where(np.isfinite(speeds), speeds, 0.0) ** 2
    n = u.shape[1]

    def design(rows):
        zeros = np.zeros((rows.sum(), n))
        return np.vstack([
            np.hstack([u[rows] * positions[:, 1], zeros]),
            np.hstack([-u[rows] * positions[:, 0], zeros]),
            np.hstack([zeros, u[rows] * signs]),
        ])

    target = np.concatenate([torque[inner, 0], torque[inner, 1], torque[inner, 2]])
    coeffs, *_ = np.linalg.lstsq(design(inner), target, rcond=None)
    all_rows = np.ones(len(log), dtype=bool)
    fitted_torque = (design(all_rows) @ coeffs).reshape(3, -1).T
    accel_fit = fitted_torque @ np.linalg.inv(vehicle_inertia).T  # gyroscopic term is small here

    def robust_var(x):  # variance of the central 99 % (glitches out, repeated samples kept)
        lo, hi = np.percentile(x, [0.5, 99.5], axis=0)
        return np.array([np.var(x[(x[:, a] >= lo[a]) & (x[:, a] <= hi[a]), a]) for a in range(3)])

    def increment_var(k):
        start = np.arange(len(log) - k)
        valid = np.ones(start.size, dtype=bool)
        for j in range(k + 1):
            valid &= ok[start + j]
        cum = np.vstack([np.zeros((1, 3)), np.cumsum(accel_fit * dt, axis=0)])
        resid = (gyro[start + k] - gyro[start]) - (cum[start + k] - cum[start])
        return robust_var(resid[valid]) if valid.sum() > 50 else None

    k_long = max(2, int(round(0.05 / dt)))
    var_1, var_k = increment_var(1), increment_var(k_long)
    if var_1 is None or var_k is None:
        return {}
    q2 = np.maximum((var_k - var_1) / ((k_long - 1) * dt), 0.0)
    sigma2 = np.maximum((var_1 - q2 * dt) / 2.0, 0.0)
    rate_hz = 1.0 / dt
    gyro_sigma = math.sqrt(float(np.mean(sigma2)))
    return {
        "gyro_sample_rate_hz": rate_hz,
        "gyro_noise_density": max(gyro_sigma, 1e-3) / math.sqrt(rate_hz),
        "rate_process_noise": max(math.sqrt(float(np.mean(q2))), 1e-3),
    }


def _nominals(vehicle: Vehicle, options: ReplayOptions, log: FlightLog) -> tuple[list[float], list[float], str]:
    n = vehicle.rotor_count
    if options.unit_inertia:
        if options.kf_nominal is not None and options.km_nominal is not None:
            return [options.kf_nominal] * n, [options.km_nominal] * n, "given"
        # Start from the log's own band-limited torque fit (J = 1): a data-driven prior.
        checks = check_log(log, vehicle, bands={"band": (1.0, 10.0)}, unit_inertia=True)
        entry = checks["bands"].get("band")
        if not entry:
            raise UserError("unit-inertia mode: no flying segment to initialise kf/J and km/J from; give --kf-nominal/--km-nominal")
        kf = 0.5 * (entry["roll_kf"]["kf"] + entry["pitch_kf"]["kf"])
        km = entry["yaw_km_rotor_inertia"]["km"]
        if not (kf > 0 and km > 0):
            raise UserError(
                f"unit-inertia mode: the log's torque fit gives kf/J = {kf:.3g}, km/J = {km:.3g}: not positive, "
                "so the vehicle file's geometry or yaw signs disagree with the data; give --kf-nominal/--km-nominal"
            )
        kf = options.kf_nominal if options.kf_nominal is not None else kf
        km = options.km_nominal if options.km_nominal is not None else km
        return [kf] * n, [km] * n, "band-limited least-squares torque fit of this log (1-10 Hz, J = 1)"
    kf = [options.kf_nominal] * n if options.kf_nominal is not None else vehicle.kf_nominal
    km = [options.km_nominal] * n if options.km_nominal is not None else vehicle.km_nominal
    if kf is None or km is None:
        raise UserError(
            f"vehicle file {vehicle.path or vehicle.name}: kf_nominal/km_nominal are null: give --kf-nominal and "
            "--km-nominal (the filter needs a prior mean)"
        )
    return list(kf), list(km), "vehicle file" if options.kf_nominal is None else "given"


def build_config(vehicle: Vehicle, log: FlightLog, options: ReplayOptions) -> tuple[dict, dict]:
    """Filter configuration fields (propid_config_t names, SI) and notes on where they came from."""
    if vehicle.inertia is None and not options.unit_inertia:
        raise UserError(
            f"vehicle file {vehicle.path or vehicle.name}: inertia is null. The filter turns torques into angular "
            "acceleration with J, so without it kf and km cannot be estimated in SI units. Run with --unit-inertia "
            "to estimate kf/J and km/Jzz ratios instead (see docs/real-data.md)"
        )
    inertia = np.eye(3) if options.unit_inertia else np.asarray(vehicle.inertia, dtype=float)
    kf, km, nominal_source = _nominals(vehicle, options, log)
    limit = options.max_rotor_speed or absurd_speed_limit(log.rotor_speed)
    config = {
        "rotor_count": vehicle.rotor_count,
        "positions": vehicle.positions.tolist(),
        "yaw_signs": vehicle.yaw_signs.tolist(),
        "thrust_coeff_nominal": kf,
        "drag_coeff_nominal": km,
        "inertia": inertia.tolist(),
        "max_rotor_speed": float(limit),
    }
    notes = {"nominals": nominal_source, "max_rotor_speed": "given" if options.max_rotor_speed else
             "2x the 99.9th percentile of the log's finite rotor speeds"}
    if options.noise == "auto":
        mask = flying_mask(log)
        auto = estimate_noise(log, inertia, vehicle.positions, vehicle.yaw_signs, mask)
        config.update(auto)
        notes["noise"] = ("auto: gyro noise and unmodelled angular acceleration measured on the log "
                          "(residual of a least-squares fit of the filter's torque model)")
    else:
        notes["noise"] = "library defaults"
    config.update(options.overrides)
    return config, notes


_INPUT_RULE: dict = {}


def filter_input_rule() -> str:
    """How the loaded C library turns rotor samples into the input of one prediction step
    (t_k-1, t_k]: "zoh" (the latest rotor sample) or "trapezoid" (mean of the sample that was
    latest at t_k-1 and the latest one). Found by probing the library through its API, once:
    a symmetric quad, negligible measurement weight, one step in which a single rotor speeds
    up; the predicted rate change is the full step (zoh) or half of it (trapezoid)."""
    if "rule" in _INPUT_RULE:
        return _INPUT_RULE["rule"]
    from propid import cfilter

    arm, kf, inertia = 0.1, 1e-6, 1e-3
    config = cfilter.FilterConfig.symmetric(4, arm, math.pi / 4, 1.0, kf, 1e-8, [inertia] * 3,
                                            rate_std0=1e-4, gyro_noise_density=10.0, gyro_sample_rate_hz=100.0,
                                            gate_sigma=0.0, thrust_coeff_rel_std0=1e-3, drag_coeff_rel_std0=1e-3,
                                            gyro_bias_std0=1e-4)
    probe = cfilter.CFilter(config)
    base, fast = [500.0] * 4, [1000.0, 500.0, 500.0, 500.0]
    for k, speeds in enumerate((base, base, fast)):
        t_us = US + k * 10_000
        probe.push_rotor_speeds(t_us, speeds)
        probe.push_gyro(t_us, [0.0, 0.0, 0.0])
    position = np.array(config.positions[0])
    torque = kf * (fast[0] ** 2 - base[0] ** 2) * np.array([position[1], -position[0]])
    full_step = 0.01 * torque / inertia
    ratio = float(np.dot(probe.estimate().body_rate[:2], full_step) / np.dot(full_step, full_step))
    _INPUT_RULE["rule"] = "trapezoid" if abs(ratio - 0.5) < abs(ratio - 1.0) else "zoh"
    _INPUT_RULE["ratio"] = ratio
    return _INPUT_RULE["rule"]


DELAY_BAND_HZ = (2.0, 10.0)
MAX_ROTOR_DELAY_S = 0.05


def estimate_rotor_delay(log: FlightLog, vehicle: Vehicle, mask: np.ndarray | None = None,
                         unit_inertia: bool = False) -> float:
    """Delay of the angular-acceleration response behind the logged rotor speeds, in whole
    samples of the log, by the filter's own discretisation: the replay pushes rotor sample n
    at t_n + m dt before gyro sample n + m, so the Euler step (t_{n+m-1}, t_{n+m}] integrates
    u[n]. The rule regresses the measured torque of that step, J (w[k] - w[k-1])/dt + w x Jw,
    on the model's roll and pitch regressors u[k - m] (with a trapezoidal library input,
    0.5 (u[k - m] + u[k - m - 1]): filter_input_rule) (both band-passed to 2-10 Hz per flying
    segment) for m = 0 .. 50 ms and takes the m with the largest R^2 (sum over roll and
    pitch), i.e. the peak of the normalised cross-correlation of modelled and measured
    torque. Scale-free: it uses no coefficient value."""
    from propid.realdata_checks import clean_rotor_speeds, lagged_fit, segments

    steps = np.diff(log.t)
    dt = float(np.median(steps[steps > 0]))
    rate = 1.0 / dt
    if DELAY_BAND_HZ[1] >= 0.45 * rate:
        return 0.0
    inertia = np.eye(3) if unit_inertia or vehicle.inertia is None else np.asarray(vehicle.inertia)
    mask = flying_mask(log) if mask is None else mask
    uniform = np.ones(len(log), dtype=bool)
    uniform[1:] &= np.abs(steps - dt) < 0.5 * dt
    segs = segments(mask & uniform, int(max(2.0 * rate, 50)))
    if not segs:
        return 0.0
    speeds, _ = clean_rotor_speeds(log.rotor_speed, absurd_speed_limit(log.rotor_speed))
    gyro = _hold_gaps(log.gyro, ~np.isfinite(log.gyro))
    step_rate = np.zeros_like(gyro)
    step_rate[1:] = (gyro[1:] - gyro[:-1]) / dt
    torque = step_rate @ inertia.T + np.cross(gyro, gyro @ inertia.T)
    u = speeds**2
    if filter_input_rule() == "trapezoid":  # the step integrates the mean of the previous and the latest sample
        u = np.vstack([u[:1], 0.5 * (u[1:] + u[:-1])])
    pos = vehicle.positions
    regs = [(u * pos[:, 1]).sum(axis=1, keepdims=True), (-u * pos[:, 0]).sum(axis=1, keepdims=True)]
    segs = [(max(a, 1), b) for a, b in segs]  # the first row of a segment has no step
    best, best_score = 0, -np.inf
    for lag in range(0, int(round(MAX_ROTOR_DELAY_S * rate)) + 1):
        score = sum(lagged_fit(torque[:, axis], regs[axis], segs, rate, DELAY_BAND_HZ, range(lag, lag + 1)).r2
                    for axis in range(2))
        if np.isfinite(score) and score > best_score:
            best, best_score = lag, score
    return best * dt


def _field(obj, name):
    """Read a field from a dict, a dataclass or a ctypes structure alike."""
    value = obj[name] if isinstance(obj, dict) else getattr(obj, name)
    if hasattr(value, "_length_") or isinstance(value, (list, tuple, np.ndarray)):
        return [float(v) for v in value]
    return value


class FilterSession:
    """The firmware filter (engineer F's ctypes binding, propid.cfilter) behind the few
    calls the replay needs; estimates come back as plain lists of floats."""

    def __init__(self, vehicle: Vehicle, config_fields: dict):
        from propid import cfilter  # the C library itself, not a Python re-implementation

        self._cfilter = cfilter
        geometry = {"rotor_count", "positions", "yaw_signs", "thrust_coeff_nominal", "drag_coeff_nominal", "inertia"}
        self.vehicle = Vehicle(
            name=vehicle.name,
            rotors=vehicle.rotors,
            mass=vehicle.mass,
            inertia=np.asarray(config_fields["inertia"], dtype=float),
            kf_nominal=list(config_fields["thrust_coeff_nominal"]),
            km_nominal=list(config_fields["drag_coeff_nominal"]),
            rotor_radius=vehicle.rotor_radius,
            rotor_inertia=vehicle.rotor_inertia,
            notes=vehicle.notes,
            path=vehicle.path,
        )
        overrides = {k: v for k, v in config_fields.items() if k not in geometry}
        try:
            config = cfilter.FilterConfig.from_vehicle(self.vehicle.to_json_dict(), **overrides)
            self._filter = cfilter.CFilter(config)
        except (ValueError, TypeError) as exc:
            raise UserError(f"the filter rejected its configuration: {exc}") from None
        self.rotor_count = vehicle.rotor_count
        self.TIME_JUMP = cfilter.STATUS["PROPID_ERR_TIME_JUMP"]

    def push_rotor_speeds(self, t_us: int, speeds: np.ndarray) -> int:
        return int(self._filter.push_rotor_speeds(t_us, speeds))

    def push_gyro(self, t_us: int, gyro: np.ndarray) -> int:
        return int(self._filter.push_gyro(t_us, gyro))

    def resync(self, t_us: int) -> int:
        return int(self._filter.resync(t_us))

    def status_name(self, code: int) -> str:
        return str(self._filter.status_name(code))

    def estimate(self) -> dict:
        est = self._filter.estimate()
        names = ("thrust_coeff", "thrust_coeff_std", "drag_coeff", "drag_coeff_std", "gyro_bias", "gyro_bias_std",
                 "thrust_coeff_converged", "drag_coeff_converged", "health", "innovation_test_ratio")
        return {name: _field(est, name) for name in names}

    def counters(self) -> dict:
        return dict(self._filter.counters())


def _segment_mask(log: FlightLog, segment: str) -> np.ndarray:
    if segment == "all":
        return np.ones(len(log), dtype=bool)
    if segment == "flying":
        return flying_mask(log)
    raise UserError(f"--segment {segment!r}: choose all or flying")


def replay(log: FlightLog, vehicle: Vehicle, options: ReplayOptions | None = None) -> ReplayResult:
    """Run the log through the C filter; return the summary (JSON-ready) and time series."""
    options = options or ReplayOptions()
    if log.rotor_count != vehicle.rotor_count:
        raise UserError(f"the log has {log.rotor_count} rotors, the vehicle file {vehicle.rotor_count}")
    if options.noise == "nis":
        return _replay_nis(log, vehicle, options)
    streams = detect_streams(log) if options.streams == "auto" else options.streams
    logged_streams = streams  # --skip-repeats turns a rows log into events below; the time base stays the rows'
    mask = _segment_mask(log, options.segment)
    rows = np.flatnonzero(mask)
    if rows.size == 0:
        raise UserError("no rows to replay (is the vehicle ever flying? try --segment all)")
    recorded = log
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
    if prefilter_info is not None:
        notes["prefilter"] = prefilter_info
    if highpass_info is not None:
        notes["diagnostic_highpass"] = highpass_info
    filt = FilterSession(vehicle, config_fields)
    t_us = np.round((log.t - log.t[0]) * US).astype(np.int64) + US  # start at 1 s: time 0 is 'no time yet'
    speeds = np.ascontiguousarray(log.rotor_speed, dtype=np.float32)
    gyro = np.ascontiguousarray(log.gyro, dtype=np.float32)
    has_gyro = np.any(np.isfinite(log.gyro), axis=1)
    has_rotor = np.any(np.isfinite(log.rotor_speed), axis=1)
    repeats = {"gyro": 0, "rotor": 0}
    if options.skip_repeats:
        same_gyro = np.zeros(len(log), dtype=bool)
        same_gyro[1:] = np.all(log.gyro[1:] == log.gyro[:-1], axis=1)
        same_rotor = np.zeros(len(log), dtype=bool)
        same_rotor[1:] = np.all(log.rotor_speed[1:] == log.rotor_speed[:-1], axis=1)
        repeats = {"gyro": int(np.sum(same_gyro[mask])), "rotor": int(np.sum(same_rotor[mask]))}
        has_gyro &= ~same_gyro
        has_rotor &= ~same_rotor
        if streams == "rows":
            streams = "events"  # rows now carry one stream or the other
    if options.rotor_delay_s == "auto" and logged_streams == "rows":
        rotor_delay_s = estimate_rotor_delay(log, vehicle, mask, unit_inertia=options.unit_inertia)
        delay_rule = ("auto: whole-sample lag (0-50 ms) maximising the 2-10 Hz R^2 of measured vs modelled "
                      "roll/pitch torque in the filter's Euler step")
    elif options.rotor_delay_s == "auto":
        rotor_delay_s = 0.0  # event-style logs carry each stream's own time stamps
        delay_rule = "auto: 0 for an event-style log (each stream keeps its own time stamps)"
    else:
        rotor_delay_s = float(options.rotor_delay_s)
        delay_rule = "given"
    delay_us = int(round(rotor_delay_s * US))
    status_counts: dict[str, int] = {}
    n = vehicle.rotor_count
    rec_t, rec_kf, rec_kfs, rec_km, rec_kms, rec_bg, rec_bgs, rec_conv_kf, rec_conv_km, rec_nis = ([] for _ in range(10))
    from propid.cfilter import DEFAULT_TUNING

    gate = float(config_fields.get("gate_sigma", DEFAULT_TUNING["gate_sigma"]))
    resyncs = 0
    gyro_pushes = 0
    iterator = rows
    if options.progress:
        from tqdm import tqdm

        iterator = tqdm(rows, desc="replay", unit="row", mininterval=0.5, leave=False)
    # Rotor rows are pushed at t + delay: interleave the two streams in time order.
    rotor_rows = [i for i in rows if streams == "rows" or has_rotor[i]]
    next_rotor = 0
    for i in iterator:
        while next_rotor < len(rotor_rows) and t_us[rotor_rows[next_rotor]] + delay_us <= t_us[i]:
            j = rotor_rows[next_rotor]
            next_rotor += 1
            status = filt.push_rotor_speeds(int(t_us[j] + delay_us), speeds[j])
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
            gyro_pushes += 1
            if gyro_pushes % options.record_every == 0:
                est = filt.estimate()
                rec_t.append(log.t[i])
                rec_kf.append(est["thrust_coeff"][:n])
                rec_kfs.append(est["thrust_coeff_std"][:n])
                rec_km.append(est["drag_coeff"][:n])
                rec_kms.append(est["drag_coeff_std"][:n])
                rec_bg.append(est["gyro_bias"])
                rec_bgs.append(est["gyro_bias_std"])
                rec_conv_kf.append([(est["thrust_coeff_converged"] >> k) & 1 for k in range(n)])
                rec_conv_km.append([(est["drag_coeff_converged"] >> k) & 1 for k in range(n)])
                rec_nis.append(est["innovation_test_ratio"] if status >= 0 else [np.nan] * 3)
    if not rec_t:
        raise UserError("no gyro sample was replayed")
    series = {
        "t": np.array(rec_t),
        "kf": np.array(rec_kf, dtype=float),
        "kf_std": np.array(rec_kfs, dtype=float),
        "km": np.array(rec_km, dtype=float),
        "km_std": np.array(rec_kms, dtype=float),
        "gyro_bias": np.array(rec_bg, dtype=float),
        "gyro_bias_std": np.array(rec_bgs, dtype=float),
        "kf_converged": np.array(rec_conv_kf, dtype=bool),
        "km_converged": np.array(rec_conv_km, dtype=bool),
        "nis": np.array(rec_nis, dtype=float) * (gate * gate if gate > 0 else np.nan),
    }
    final = filt.estimate()
    counters = filt.counters()

    def converged_mean(values: np.ndarray, flags: np.ndarray) -> tuple[list[float], list[bool], list[float]]:
        means, conv, starts = [], [], []
        half = values.shape[0] // 2
        for k in range(values.shape[1]):
            on = np.flatnonzero(flags[:, k])
            start = int(on[0]) if on.size else half
            means.append(float(np.mean(values[start:, k])))
            conv.append(bool(on.size) and bool(flags[-1, k]))
            starts.append(float(series["t"][start]) if on.size else float("nan"))
        return means, conv, starts

    kf_mean, kf_conv, kf_start = converged_mean(series["kf"], series["kf_converged"])
    km_mean, km_conv, km_start = converged_mean(series["km"], series["km_converged"])
    finite = all(np.all(np.isfinite(series[k])) for k in ("kf", "kf_std", "km", "km_std", "gyro_bias"))
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
        "streams": streams,
        "rows_replayed": int(rows.size),
        "repeated_rows_skipped": repeats,
        "rotor_delay_s": rotor_delay_s,
        "rotor_delay_rule": delay_rule,
        "filter_rotor_input": filter_input_rule(),
        "duration_s": float(log.t[rows[-1]] - log.t[rows[0]]),
        "kf": [float(v) for v in final["thrust_coeff"][:n]],
        "kf_std": [float(v) for v in final["thrust_coeff_std"][:n]],
        "km": [float(v) for v in final["drag_coeff"][:n]],
        "km_std": [float(v) for v in final["drag_coeff_std"][:n]],
        "kf_mean": kf_mean,
        "km_mean": km_mean,
        "kf_converged_from_s": kf_start,
        "km_converged_from_s": km_start,
        "converged": {"kf": kf_conv, "km": km_conv},
        "gyro_bias": [float(v) for v in final["gyro_bias"]],
        "gyro_bias_std": [float(v) for v in final["gyro_bias_std"]],
        "rejected": dict(sorted(status_counts.items())),
        "nis_mean": nis_mean(series),
        "counters": counters,
        "resyncs_by_replay": resyncs,
        "health": int(final["health"]),
        "finite": bool(finite),
        "config": config_fields,
        "config_notes": notes,
        "definitions": {
            "kf_mean": "mean of the estimate from the first sample flagged converged (rel std < converged_rel_std) "
                       "to the end; second half of the replay if never converged",
            "converged": "converged flag set at the end of the replay",
        },
    }
    return ReplayResult(summary=summary, series=series)


NIS_TOLERANCE = 0.05
NIS_MAX_ITERATIONS = 8


def _replay_nis(log: FlightLog, vehicle: Vehicle, options: ReplayOptions) -> ReplayResult:
    """--noise nis: gyro noise by the 'auto' rule, then rate_process_noise q scaled until the
    filter's own innovations are consistent with it: mean normalised innovation squared
    nu^2/S over the gyro axes = 1 (within NIS_TOLERANCE). nu^2/S ~ 1/q^2 when the process
    noise dominates S; secant steps on log NIS against log q converge in a few replays.
    Uses no coefficient value."""
    from dataclasses import replace

    base = replace(options, noise="auto")
    given = options.overrides.get("rate_process_noise")
    q = float(given) if given else float(build_config(vehicle, log, replace(base, overrides={}))[0].get(
        "rate_process_noise", 1.0))
    history = []
    result = None
    for _ in range(NIS_MAX_ITERATIONS):
        result = replay(log, vehicle, replace(base, overrides={**options.overrides, "rate_process_noise": q}))
        nis = result.summary["nis_mean"]
        history.append({"rate_process_noise": q, "nis_mean": nis})
        if not np.isfinite(nis) or nis <= 0 or abs(nis - 1.0) < NIS_TOLERANCE:
            break
        # secant step on log NIS vs log q (slope -2 when the process noise dominates S)
        slope = -2.0
        if len(history) >= 2:
            (q0, n0), (q1, n1) = [(h["rate_process_noise"], h["nis_mean"]) for h in history[-2:]]
            if q0 != q1 and n0 > 0 and n1 > 0:
                slope = float(np.clip(math.log(n1 / n0) / math.log(q1 / q0), -2.0, -0.1))
        q = float(np.clip(q * math.exp(-math.log(nis) / slope), 1e-4, 1e4))
    result.summary["config_notes"]["noise"] = (
        "nis: gyro noise by the auto rule; rate_process_noise scaled until the mean normalised innovation "
        "squared of this replay is 1")
    result.summary["config_notes"]["nis_iterations"] = history
    return result


def nis_mean(series: dict, skip_s: float = 2.0) -> float:
    """Mean normalised innovation squared nu^2/S over the gyro axes and the accepted samples
    after the first skip_s seconds (1 for a consistent filter)."""
    nis = series.get("nis")
    if nis is None or nis.size == 0:
        return float("nan")
    late = series["t"] >= series["t"][0] + skip_s
    values = nis[late] if late.any() else nis
    return float(np.nanmean(values)) if np.isfinite(values).any() else float("nan")


def plot_replay(result: ReplayResult, path: str, title: str = "", reference_kf: float | None = None) -> None:
    """PNG: kf and km per rotor with +-1 sigma bands, gyro biases, over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = result.series
    fig, axes = plt.subplots(3, 1, figsize=(7.5, 7.0), sharex=True, dpi=80)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, key, label in ((axes[0], "kf", "kf"), (axes[1], "km", "km")):
        for k in range(s[key].shape[1]):
            c = colors[k % len(colors)]
            ax.plot(s["t"], s[key][:, k], color=c, lw=1.0, label=f"rotor {k + 1}")
            ax.fill_between(s["t"], s[key][:, k] - s[f"{key}_std"][:, k], s[key][:, k] + s[f"{key}_std"][:, k],
                            color=c, alpha=0.15, lw=0)
        nominal = result.summary["config"]["thrust_coeff_nominal" if key == "kf" else "drag_coeff_nominal"]
        ax.axhline(float(np.mean(nominal)), color="k", ls=":", lw=1, label="prior mean")
        ax.set_ylabel(f"{label} [{result.summary['units'][key].split(':')[0]}]")
        ax.grid(alpha=0.3)
    if reference_kf is not None:
        axes[0].axhline(reference_kf, color="r", ls="--", lw=1, label="independent (thrust)")
    axes[0].legend(fontsize=7, ncol=3, loc="lower right")
    for k, axis in enumerate("xyz"):
        c = colors[k]
        axes[2].plot(s["t"], s["gyro_bias"][:, k], color=c, lw=1.0, label=f"b_{axis}")
        axes[2].fill_between(s["t"], s["gyro_bias"][:, k] - s["gyro_bias_std"][:, k],
                             s["gyro_bias"][:, k] + s["gyro_bias_std"][:, k], color=c, alpha=0.15, lw=0)
    axes[2].set_ylabel("gyro bias [rad/s]")
    axes[2].set_xlabel("log time [s]")
    axes[2].legend(fontsize=7, ncol=3)
    axes[2].grid(alpha=0.3)
    if title:
        axes[0].set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# ----------------------------------------------------------------------------- fleet validation
def _cv(values: list[float]) -> float:
    arr = np.asarray(values, dtype=float)
    return float(np.std(arr, ddof=1) / np.mean(arr)) if arr.size > 1 and np.mean(arr) != 0 else float("nan")


def fleet_summary(summaries: list[dict], reference_kf: float | None = None) -> dict:
    """Statistics over several replays of one vehicle: mean of the per-run means (over
    rotors), their coefficient of variation (std/mean, ddof 1), agreement with the
    independent kf, and the same for the least-squares checks when they were run."""
    kf_runs = [float(np.mean(s["kf_mean"])) for s in summaries]
    km_runs = [float(np.mean(s["km_mean"])) for s in summaries]
    out = {
        "runs": len(summaries),
        "kf_fleet_mean": float(np.mean(kf_runs)),
        "kf_run_cv": _cv(kf_runs),
        "km_fleet_mean": float(np.mean(km_runs)),
        "km_run_cv": _cv(km_runs),
        "all_finite": all(s["finite"] for s in summaries),
        "kf_converged_runs": sum(all(s["converged"]["kf"]) for s in summaries),
        "runs_with_state_clamps": sum(1 for s in summaries if s["counters"].get("state_clamps", 0) > 0),
        "cov_repairs": sum(s["counters"].get("cov_repairs", 0) for s in summaries),
        "km_converged_runs": sum(all(s["converged"]["km"]) for s in summaries),
    }
    if reference_kf:
        out["reference_kf"] = reference_kf
        out["kf_fleet_over_reference"] = out["kf_fleet_mean"] / reference_kf
    checks = [s.get("checks") for s in summaries]
    if all(c and c.get("bands") for c in checks):
        def pooled(band, key, coeff):
            vals = [c["bands"][band][key][coeff] for c in checks if band in c["bands"] and key in c["bands"][band]]
            return {"mean": float(np.mean(vals)), "cv": _cv(vals)} if vals else None

        out["checks"] = {
            "thrust_kf_raw": pooled("raw", "thrust_kf", "kf"),
            "roll_kf_raw": pooled("raw", "roll_kf", "kf"),
            "pitch_kf_raw": pooled("raw", "pitch_kf", "kf"),
            "roll_kf_raw_with_velocity": pooled("raw", "roll_kf_with_velocity", "kf"),
            "pitch_kf_raw_with_velocity": pooled("raw", "pitch_kf_with_velocity", "kf"),
            "roll_kf_2_10Hz": pooled("2-10Hz", "roll_kf", "kf"),
            "pitch_kf_2_10Hz": pooled("2-10Hz", "pitch_kf", "kf"),
            "yaw_km_2_10Hz_with_rotor_inertia": pooled("2-10Hz", "yaw_km_rotor_inertia", "km"),
        }
    return out


def validation_table(summaries: list[dict], reference_kf: float | None = None) -> str:
    """Markdown table, one row per run (the docs' validation table)."""
    ref = reference_kf or float("nan")
    head = ("| run | s | rotor delay [ms] | rotor samples rejected | gated gyro axes | clamped steps | filter kf (x ref) | kf rotor spread | filter km | km conv. "
            "| acc thrust kf | LS roll/pitch kf raw | raw + velocity moment | 2-10 Hz | 2-10 Hz km |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for s in summaries:
        kf = np.asarray(s["kf_mean"])
        name = Path(s["log"]).stem if s.get("log") else "?"
        rejected = sum(v for k, v in s["rejected"].items() if k in ("PROPID_ERR_NOT_FINITE", "PROPID_ERR_ROTOR_SPEED_RANGE"))
        c = (s.get("checks") or {}).get("bands", {})

        def fit(band, key, coeff="kf", fmt="{:.2f}"):
            try:
                return fmt.format(c[band][key][coeff] / ref) if coeff == "kf" else fmt.format(c[band][key][coeff])
            except KeyError:
                return "n/a"

        lines.append(
            f"| {name} | {s['duration_s']:.0f} | {1e3 * s.get('rotor_delay_s', 0.0):.0f} | {rejected} | "
            f"{sum(s['counters'].get('axis_gated', [0]))} | {s['counters'].get('state_clamps', 0)} | "
            f"{kf.mean():.3g} ({kf.mean() / ref:.2f}) | "
            f"{_cv(kf):.0%} | {np.mean(s['km_mean']):.3g} | {sum(s['converged']['km'])}/{len(kf)} | "
            f"{fit('raw', 'thrust_kf')} | {fit('raw', 'roll_kf')}/{fit('raw', 'pitch_kf')} | "
            f"{fit('raw', 'roll_kf_with_velocity')}/{fit('raw', 'pitch_kf_with_velocity')} | "
            f"{fit('2-10Hz', 'roll_kf')}/{fit('2-10Hz', 'pitch_kf')} | "
            f"{fit('2-10Hz', 'yaw_km_rotor_inertia', 'km', '{:.2g}')} |"
        )
    return "\n".join(lines)


def plot_fleet(summaries: list[dict], path: str, reference_kf: float) -> None:
    """Bar chart per run: the filter's kf and the least-squares checks, relative to the
    independent kf."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [Path(s["log"]).stem.replace("_20251017", "") if s.get("log") else "?" for s in summaries]
    series = {"filter (mean of rotors)": [np.mean(s["kf_mean"]) / reference_kf for s in summaries]}

    def check(band, key):
        return [((s.get("checks") or {}).get("bands", {}).get(band, {}).get(key, {}) or {}).get("kf", np.nan)
                / reference_kf for s in summaries]

    if all(s.get("checks") for s in summaries):
        series["LS thrust from acc_z"] = check("raw", "thrust_kf")
        series["LS torque raw (roll+pitch)/2"] = list(0.5 * (np.array(check("raw", "roll_kf")) + np.array(check("raw", "pitch_kf"))))
        series["LS torque 2-10 Hz (roll+pitch)/2"] = list(
            0.5 * (np.array(check("2-10Hz", "roll_kf")) + np.array(check("2-10Hz", "pitch_kf"))))
    fig, ax = plt.subplots(figsize=(9, 3.6), dpi=80)
    width = 0.8 / len(series)
    x = np.arange(len(names))
    for k, (label, values) in enumerate(series.items()):
        ax.bar(x + (k - (len(series) - 1) / 2) * width, values, width, label=label)
    ax.axhline(1.0, color="k", lw=1, ls="--")
    ax.set_xticks(x)
    ax.set_xticklabels(names, rotation=45, ha="right", fontsize=7)
    ax.set_ylabel("kf / independent kf")
    ax.set_ylim(0, 1.25)
    ax.legend(fontsize=7, ncol=4, loc="upper center")
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# ----------------------------------------------------------------------------- matched pre-filter
# A causal low-pass applied identically to the gyro and to the rotor-speed-squared stream
# (docs/real-data.md, "Matched pre-filter"). The rate dynamics J dw/dt = B(kf, km) u are
# linear in u = Omega^2 (up to the small gyroscopic term), so one LTI filter H on both
# sides keeps J d(Hw)/dt = B(kf, km) (Hu) with the SAME coefficients, while removing the
# band in which the torque model does not explain the measured angular acceleration.
# The filter is two identical first-order sections in cascade (critically damped, 2nd
# order): its impulse response is non-negative, so filtered Omega^2 stays >= 0 and can be
# pushed as the rotor speed sqrt(H u). A high-pass part cannot be pushed (it makes u
# negative); removing slow content needs a disturbance-torque state in the filter.

CASCADE_3DB = math.sqrt(math.sqrt(2.0) - 1.0)  # -3 dB frequency of two equal 1st-order sections / their pole frequency
COHERENCE_THRESHOLD = 0.5
COHERENCE_WINDOW_S = 2.56


def lowpass_pole(cutoff_hz: float, rate_hz: float) -> float:
    """Pole a of each first-order section y[n] = a y[n-1] + (1 - a) x[n], chosen so that the
    cascade of two has its -3 dB point at cutoff_hz."""
    if not (cutoff_hz > 0 and rate_hz > 0):
        raise UserError(f"pre-filter cut-off {cutoff_hz} Hz at {rate_hz} Hz: both must be positive")
    pole_hz = cutoff_hz / CASCADE_3DB
    return math.exp(-2.0 * math.pi * pole_hz / rate_hz)


def matched_lowpass(x: np.ndarray, pole: float, starts: np.ndarray) -> np.ndarray:
    """Two first-order sections in cascade along axis 0, restarted (at the input value:
    no start-up transient) at every index in `starts`. Unit DC gain; the impulse response
    (1-a)^2 (n+1) a^n is non-negative."""
    out = np.empty_like(x, dtype=float)
    restart = np.zeros(x.shape[0], dtype=bool)
    restart[starts] = True
    restart[0] = True
    gain = 1.0 - pole
    s1 = s2 = x[0].astype(float)
    for n in range(x.shape[0]):
        if restart[n]:
            s1 = s2 = x[n].astype(float)
        s1 = pole * s1 + gain * x[n]
        s2 = pole * s2 + gain * s1
        out[n] = s2
    return out


def noise_gain(pole: float) -> float:
    """sum of h[n]^2 of the cascade: the variance ratio of white noise through it."""
    n = np.arange(int(20 / max(1e-9, 1.0 - pole)) + 50)
    h = (1.0 - pole) ** 2 * (n + 1) * pole**n
    return float(np.sum(h**2))


def _hold_gaps(x: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Replace bad samples by the last good one before them (the next good one at the start),
    i.e. what the filter itself does with a rejected rotor sample (zero-order hold)."""
    out = x.copy()
    for k in range(x.shape[1]):
        good = np.flatnonzero(~bad[:, k])
        if good.size == 0:
            continue
        idx = np.searchsorted(good, np.arange(x.shape[0]), side="right") - 1
        idx = np.where(idx < 0, 0, idx)
        out[:, k] = x[good[idx], k]
    return out


def torque_coherence(log: FlightLog, vehicle: Vehicle, mask: np.ndarray, inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Magnitude-squared coherence between the torque model's roll/pitch regressors
    (sum y_i Omega_i^2, sum -x_i Omega_i^2) and the measured torque J dw/dt + w x Jw, per
    frequency (Welch: Hann windows of COHERENCE_WINDOW_S, 50 % overlap, within the flying
    segments). Returns (frequencies, coherence averaged over roll and pitch). Lag-free and
    scale-free: it uses no coefficient value and no stream alignment."""
    from propid.realdata_checks import clean_rotor_speeds, segments

    steps = np.diff(log.t)
    dt = float(np.median(steps[steps > 0]))
    nper = max(16, int(round(COHERENCE_WINDOW_S / dt)))
    speeds, _ = clean_rotor_speeds(log.rotor_speed, absurd_speed_limit(log.rotor_speed))
    u = speeds**2
    gyro = _hold_gaps(log.gyro, ~np.isfinite(log.gyro))
    rate_dot = np.gradient(gyro, log.t, axis=0)
    torque = rate_dot @ inertia.T + np.cross(gyro, gyro @ inertia.T)
    pos = vehicle.positions
    regs = [(u * pos[:, 1]).sum(axis=1), (-u * pos[:, 0]).sum(axis=1)]
    window = np.hanning(nper)
    freqs = np.fft.rfftfreq(nper, dt)
    coherence = []
    for axis in range(2):
        sxx = syy = sxy = 0.0
        for a, b in segments(mask, nper):
            for s in range(a, b - nper + 1, nper // 2):
                x = regs[axis][s : s + nper]
                y = torque[s : s + nper, axis]
                fx = np.fft.rfft((x - x.mean()) * window)
                fy = np.fft.rfft((y - y.mean()) * window)
                sxx = sxx + np.abs(fx) ** 2
                syy = syy + np.abs(fy) ** 2
                sxy = sxy + np.conj(fx) * fy
        if np.isscalar(sxx):
            return freqs, np.full(freqs.shape, np.nan)
        with np.errstate(invalid="ignore", divide="ignore"):
            coherence.append(np.abs(sxy) ** 2 / (sxx * syy))
    return freqs, 0.5 * (coherence[0] + coherence[1])


COHERENCE_SMOOTH_HZ = 2.0


def coherence_cutoff(freqs: np.ndarray, coherence: np.ndarray, low_hz: float = 2.0,
                     threshold: float = COHERENCE_THRESHOLD) -> float | None:
    """The pre-filter cut-off rule: the coherence is smoothed by a moving average over
    COHERENCE_SMOOTH_HZ; from the best-explained frequency between low_hz and 4 x low_hz
    (robust to a dip at the low edge) upwards, the first frequency at which it falls below
    the threshold. None if it is below the threshold there (the torque model explains no
    band of this log)."""
    width = max(1, int(round(COHERENCE_SMOOTH_HZ / (freqs[1] - freqs[0]))) | 1)
    smooth = np.convolve(np.nan_to_num(coherence, nan=0.0), np.ones(width) / width, mode="same")
    lo, hi = int(np.searchsorted(freqs, low_hz)), int(np.searchsorted(freqs, 4.0 * low_hz))
    if lo >= freqs.size:
        return None
    start = lo + int(np.argmax(smooth[lo : max(hi, lo + 1)]))
    if smooth[start] < threshold:
        return None
    below = np.flatnonzero(smooth[start:] < threshold)
    return float(freqs[start + below[0]]) if below.size else float(freqs[-1])


def prefilter_log(log: FlightLog, vehicle: Vehicle, mask: np.ndarray, cutoff: float | str,
                  inertia: np.ndarray) -> tuple[FlightLog, dict]:
    """The log as the filter sees it with the matched pre-filter: gyro -> H gyro, rotor speed ->
    sqrt(H Omega^2), same time stamps. Missing or absurd rotor speeds (and missing gyro
    samples) are held at the previous good value first: a recursive filter needs every
    sample, and holding is what the filter does with a rejected rotor sample anyway. The
    filter restarts at every contiguous replayed segment (no start-up transient)."""
    steps = np.diff(log.t)
    dt = float(np.median(steps[steps > 0]))
    rate = 1.0 / dt
    info: dict = {"rule": "given"}
    if cutoff == "auto":
        freqs, coherence = torque_coherence(log, vehicle, mask, inertia)
        found = coherence_cutoff(freqs, coherence)
        info.update(rule=f"auto: from the best-explained frequency in 2-8 Hz upwards, the first frequency where the roll/pitch "
                         f"torque-model coherence (Welch, {COHERENCE_WINDOW_S} s windows, {COHERENCE_SMOOTH_HZ} Hz "
                         f"moving average) falls below {COHERENCE_THRESHOLD}",
                    coherence_hz=[float(f) for f in freqs[::4]], coherence=[float(c) for c in coherence[::4]])
        if found is None:
            info["note"] = "the torque model explains no band above 2 Hz of this log: no pre-filter applied"
            info["cutoff_hz"] = None
            return log, info
        cutoff = found
    cutoff = float(cutoff)
    if cutoff >= 0.45 * rate:
        info.update(cutoff_hz=cutoff, note="cut-off at or above 0.45 x the sample rate: no pre-filter applied")
        return log, info
    pole = lowpass_pole(cutoff, rate)
    limit = absurd_speed_limit(log.rotor_speed)
    bad_rotor = ~np.isfinite(log.rotor_speed) | (np.nan_to_num(log.rotor_speed, nan=0.0) > limit)
    bad_gyro = ~np.isfinite(log.gyro)
    speeds = _hold_gaps(log.rotor_speed, bad_rotor)
    gyro = _hold_gaps(log.gyro, bad_gyro)
    gap = np.concatenate([[True], (steps > 1.5 * dt)])  # a time gap restarts the filter too
    starts = np.flatnonzero(mask & (gap | ~np.concatenate([[False], mask[:-1]])))
    filtered_u = matched_lowpass(np.nan_to_num(speeds, nan=0.0) ** 2, pole, starts)
    filtered_gyro = matched_lowpass(np.nan_to_num(gyro, nan=0.0), pole, starts)
    out = FlightLog(t=log.t, gyro=filtered_gyro, rotor_speed=np.sqrt(np.maximum(filtered_u, 0.0)),
                    extra=log.extra, path=log.path)
    info.update(cutoff_hz=cutoff, pole=pole, noise_gain=noise_gain(pole),
                held_rotor_samples=int(np.sum(np.any(bad_rotor, axis=1) & mask)),
                held_gyro_samples=int(np.sum(np.any(bad_gyro, axis=1) & mask)),
                filter="two equal first-order low-pass sections in cascade (critically damped), "
                       "applied to gyro and to rotor speed squared")
    return out, info


def highpass_emulation_log(log: FlightLog, vehicle: Vehicle, mask: np.ndarray, cutoff_hz: float) -> tuple[FlightLog, dict]:
    """DIAGNOSTIC ONLY (not an estimator mode): what the filter would read if slow content,
    where unmodelled moments dominate, were removed, as a disturbance-torque state would.
    A high-pass of Omega^2 goes negative and cannot be pushed as a speed; instead every
    rotor gets u' = (u - L u) + U0 with the same offset U0 (large enough to keep u' > 0)
    and the gyro gets w - L w (L: the matched low-pass at cutoff_hz). For a vehicle whose
    rotor positions and yaw signs sum to zero, U0 adds no torque when the rotors' kf (and
    km) are equal, so the common kf is unchanged; unequal per-rotor kf would turn U0 into a
    large constant torque, so this mode pins the rotors to a common value: per-rotor numbers
    mean nothing here."""
    positions_sum = np.abs(vehicle.positions[:, :2].sum(axis=0)).max()
    arm = float(np.abs(vehicle.positions[:, :2]).max())
    if positions_sum > 1e-6 * max(arm, 1e-9) or abs(float(np.sum(vehicle.yaw_signs))) > 0:
        raise UserError("--diagnostic-highpass needs a symmetric vehicle (rotor x, y positions and yaw signs summing to 0)")
    steps = np.diff(log.t)
    dt = float(np.median(steps[steps > 0]))
    pole = lowpass_pole(cutoff_hz, 1.0 / dt)
    limit = absurd_speed_limit(log.rotor_speed)
    bad_rotor = ~np.isfinite(log.rotor_speed) | (np.nan_to_num(log.rotor_speed, nan=0.0) > limit)
    speeds = _hold_gaps(log.rotor_speed, bad_rotor)
    gyro = _hold_gaps(log.gyro, ~np.isfinite(log.gyro))
    gap = np.concatenate([[True], (steps > 1.5 * dt)])
    starts = np.flatnonzero(mask & (gap | ~np.concatenate([[False], mask[:-1]])))
    u = np.nan_to_num(speeds, nan=0.0) ** 2
    u_high = u - matched_lowpass(u, pole, starts)
    gyro_high = np.nan_to_num(gyro, nan=0.0) - matched_lowpass(np.nan_to_num(gyro, nan=0.0), pole, starts)
    offset = max(float(np.mean(u[mask])), 1.05 * float(-u_high[mask].min()))
    out = FlightLog(t=log.t, gyro=gyro_high, rotor_speed=np.sqrt(np.maximum(u_high + offset, 0.0)),
                    extra=log.extra, path=log.path)
    return out, {"cutoff_hz": cutoff_hz, "offset_rotor_speed_sq": offset,
                 "held_rotor_samples": int(np.sum(np.any(bad_rotor, axis=1) & mask)),
                 "note": "diagnostic only: slow content removed by emulation; rotors pinned to a common kf"}
