"""Data preparation for the gap diagnosis: one Flight per log, every signal the
regressors need, on the log's own time base, with the flying segments and the
time blocks used for cross-validation.

Rules (docs/gap.md, "Data preparation"):
- rows: the flying rows of `realdata_checks.flying_mask` (is_flying column, else every
  rotor spinning), off the ground when the height is logged (more than GROUND_CONTACT_M
  above the log's landed height, `landed_height`), cut into segments of uniform timing at
  least MIN_SEGMENT_S long;
- event-style logs (rotor rows and gyro rows apart): rotor speeds are held to the
  gyro rows, rows without a gyro sample are dropped;
- missing or absurd rotor speeds (above 2x the 99.9th percentile) and isolated
  missing gyro samples are interpolated for the fits;
- repeated rows: a row whose gyro triple (or rotor speeds) equals the previous row's bit for
  bit is a logger's copy of a lost packet, not a sample; their shares are reported per log
  and stream; with `repeats="missing"` (evaluated, not the default) they are missing: Omega^2 and the measured torque are both interpolated
  across every row a copy leaves unmeasured;
- otherwise (event-style logs, `repeats="samples"`) a sample-and-held rotor stream (more
  than 20 % of the rows repeat the previous row's rotor speeds exactly) is interpolated
  between its report instants;
- derivatives by central differences on the log's time stamps; torque-axis regressors
  that are not central differences themselves get the difference's response
  (`difference_response`), so they are compared like with like;
- measured torque tau = J dw/dt + w x J w with the vehicle file's J (and its
  `gyro_scale`, if given, undone first);
- each segment is band-passed (zero phase) per `band`: torque axes high-passed at
  `highpass_hz` (the slow disturbance torque the controller cancels is a nuisance:
  removing it keeps the closed loop from dragging coefficients to 0) and low-passed
  at `lowpass_hz`; the thrust axis is only low-passed, and with `band.thrust_offset` each
  segment's mean is then removed from it (a constant per segment: the accelerometer's zero-g
  offset times the mass, so that only the collective thrust's variations set kf).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.gap.gyro_bias import MODES as GYRO_BIAS_MODES, gyro_bias_from_attitude
from propid.realdata_checks import LANDED_HEIGHT_MAX_M, _hold_rotor_rows, absurd_speed_limit, bandpass, \
    clean_rotor_speeds, flying_mask
from propid.signals import log_body_velocity, measured_torque, repeats_previous_row, segments

MIN_SEGMENT_S = 2.0
# a quarter of the hover thrust cannot hold the vehicle up: rows at the lowest height whose collective
# sum Omega^2 is below this share of the flying rows' median rest on the ground (landed_height)
LANDED_COLLECTIVE = 0.25
LANDED_MIN_ROWS = 10


class NoFlyingSegment(UserError):
    """A log without a flying segment of MIN_SEGMENT_S: nothing in it to fit (with several
    fitted logs, gap leaves such a log out and lists it; alone it is an error)."""
BLOCK_S = 2.0
GROUND_CONTACT_M = 0.03  # rows at most this far above the landed height are ground contact


@dataclass
class Band:
    highpass_hz: float = 1.0
    lowpass_hz: float = 25.0
    # the thrust axis's constant (docs/gap.md "Base model"): False, through the origin (its mean is
    # kept: kf carries the accelerometer's zero-g offset as 1 + b/g); True, each segment's mean removed
    # from the low-passed thrust axis, which fits a free constant per segment on both sides
    thrust_offset: bool = False

    def for_rate(self, rate_hz: float) -> "Band":
        """The low-pass never above a quarter of the sample rate."""
        return replace(self, lowpass_hz=min(self.lowpass_hz, 0.25 * rate_hz))


@dataclass
class Flight:
    name: str
    path: Path | None
    rate_hz: float
    t: np.ndarray
    gyro: np.ndarray  # (n,3) rad/s, gyro_scale undone
    rate_dot: np.ndarray  # (n,3)
    speed: np.ndarray  # (n,N) rad/s, cleaned
    speed_dot: np.ndarray
    torque: np.ndarray  # (n,3) measured J dw/dt + w x Jw [N m]
    specific_force_z: np.ndarray | None  # acc_z [m/s^2]
    acc: np.ndarray | None
    body_velocity: np.ndarray | None  # (n,3) m/s
    height: np.ndarray | None  # (n,) m
    cmd: np.ndarray | None  # (n,N)
    vbat: np.ndarray | None
    segs: list[tuple[int, int]]
    band: Band
    repaired_rotor_samples: int = 0
    held_rotor_fraction: float = 0.0
    repeated_rows: dict = field(default_factory=dict)  # stream quality: copies of the previous row (repeated_row_stats)
    blocks: list[tuple[int, int]] = field(default_factory=list)  # [start, stop) inside segments
    quat: np.ndarray | None = None  # (n,4) attitude w, x, y, z (body -> world): ground_effect at each hub
    gyro_bias: dict = field(default_factory=dict)  # the constant gyro bias removed (gyro_bias.py), or why not
    logged_quat: np.ndarray | None = None  # (n,4) the logged attitude whatever the options: the explainable bound's channels
    landed_height: float = 0.0  # the logged height on the ground (landed_height); contact up to GROUND_CONTACT_M above

    @property
    def rows(self) -> int:
        return sum(b - a for a, b in self.segs)

    def filtered(self, x: np.ndarray, lowpass_only: bool = False, response: bool = False) -> np.ndarray:
        """Band-pass columns of x per segment; rows outside segments are 0. `response`: also
        give x the central difference's response (difference_response), as the measured
        torque has it: for a regressor compared with J dw/dt. `lowpass_only` (the thrust axis):
        low-passed, and each segment's mean removed when the band fits the thrust offset."""
        two_d = x.ndim == 2
        xx = x if two_d else x[:, None]
        out = np.zeros_like(xx, dtype=float)
        lo = None if lowpass_only else self.band.highpass_hz
        for a, b in self.segs:
            y = bandpass(np.nan_to_num(xx[a:b]), self.rate_hz, lo, self.band.lowpass_hz)
            if lowpass_only and self.band.thrust_offset:
                y = y - y.mean(axis=0)  # the segment's constant (Frisch-Waugh: fitted on both sides)
            out[a:b] = difference_response(y, self.rate_hz) if response else y
        return out if two_d else out[:, 0]

    def shifted(self, x: np.ndarray, delay_s: float) -> np.ndarray:
        """x(t + delay) per segment by linear interpolation (ends held): undoes a
        telemetry lag of `delay_s` (negative: the stream was stamped early)."""
        if delay_s == 0.0:
            return x
        out = np.array(x, dtype=float, copy=True)
        two_d = out.ndim == 2
        cols = out if two_d else out[:, None]
        for a, b in self.segs:
            tt = self.t[a:b]
            for k in range(cols.shape[1]):
                cols[a:b, k] = np.interp(tt + delay_s, tt, x[a:b, k] if two_d else x[a:b])
        return out


def difference_response(x: np.ndarray, rate_hz: float) -> np.ndarray:
    """Columns of x given the response of a central difference against d/dt, sin(wT)/(wT)
    with T the sample interval (0.94 at 10 Hz, 0.76 at 20 Hz in a 100 Hz log; 0.98 at 25 Hz
    in a 500 Hz log). The measured angular acceleration is a central difference of the gyro,
    so it reads an oscillation that much too small: a torque regressor that is not itself a
    central difference gets the same response (a measurement model), rather than the torque
    being divided by it (which amplifies the top of the band and its noise). Mirror-padded
    FFT, as the band-pass's ends."""
    n = x.shape[0]
    xp = np.concatenate([x[::-1], x, x[::-1]])
    w = 2.0 * np.pi * np.fft.rfftfreq(xp.shape[0], d=1.0 / rate_hz) / rate_hz
    gain = np.ones_like(w)
    gain[1:] = np.sin(w[1:]) / w[1:]
    shape = (-1,) + (1,) * (x.ndim - 1)
    return np.fft.irfft(np.fft.rfft(xp, axis=0) * gain.reshape(shape), n=xp.shape[0], axis=0)[n:2 * n]


def _interp_missing(x: np.ndarray) -> np.ndarray:
    x = np.array(x, dtype=float, copy=True)
    idx = np.arange(x.shape[0])
    cols = x if x.ndim == 2 else x[:, None]
    for k in range(cols.shape[1]):
        bad = ~np.isfinite(cols[:, k])
        if bad.any() and (~bad).sum() >= 2:
            cols[bad, k] = np.interp(idx[bad], idx[~bad], cols[~bad, k])
        elif bad.all():
            cols[:, k] = 0.0
    return x


HELD_FRACTION = 0.2  # more held rows than this: the rotor stream was sample-and-held


def unhold_rotor_stream(t: np.ndarray, speeds: np.ndarray) -> tuple[np.ndarray, float]:
    """A row whose rotor speeds all equal the previous row's carries no new telemetry
    report (sample-and-hold onto a faster log). When more than HELD_FRACTION of the rows
    are held, each rotor is linearly interpolated between the report instants (the rows
    where a new report arrived), so dOmega/dt is not a train of spikes. Returns the speeds
    and the held fraction."""
    held = np.zeros(len(t), dtype=bool)
    held[1:] = np.all(speeds[1:] == speeds[:-1], axis=1)
    fraction = float(held.mean())
    if fraction <= HELD_FRACTION or (~held).sum() < 4:
        return speeds, fraction
    reports = np.flatnonzero(~held)
    out = np.empty_like(speeds)
    for k in range(speeds.shape[1]):
        out[:, k] = np.interp(t, t[reports], speeds[reports, k])
    return out, fraction


REPEATS = ("missing", "samples")  # copies of the previous row: missing samples, or fused as samples (the default, analysis.Options)


def repeated_rows(values: np.ndarray) -> np.ndarray:
    """Rows whose every column equals the previous row's bit for bit (NaN never does): a logger that
    samples separately streamed blocks by sample-and-hold writes a lost packet as such a copy. Rotor
    rows that are all zero (motors stopped) are genuine and not counted."""
    return repeats_previous_row(values) & np.any(values != 0.0, axis=1)


def repeated_row_stats(copy: np.ndarray, rows: np.ndarray) -> dict:
    """Share and count of copies among `rows` (indices), and the longest run of consecutive copies."""
    inside = copy[rows]
    longest, run = 0, 0
    for c in inside:
        run = run + 1 if c else 0
        longest = max(longest, run)
    return {"share": float(inside.mean()) if inside.size else 0.0, "count": int(inside.sum()),
            "longest_run": int(longest)}


def landed_height(height: np.ndarray | None, speeds: np.ndarray, flying: np.ndarray) -> float:
    """The logged height of the vehicle resting on the ground, which gap's ground-contact rule measures
    heights from (docs/gap.md "Data preparation"). A log whose height's zero is not the floor (the
    Crazyflie's estimate reads 0.045-0.05 m on the ground) and whose flag stays on while the rotors idle
    there would otherwise count its resting rows as flight: the ground holds the weight while sum
    Omega^2 is a tenth of the hover's. Resting rows: within GROUND_CONTACT_M of the lowest logged height
    (at most LANDED_HEIGHT_MAX_M) with a collective sum Omega^2 below LANDED_COLLECTIVE x the median of
    the flying rows'; their median height if there are LANDED_MIN_ROWS of them, else 0 (the height is
    above the ground, as the SITL logs it; a flight that never rests on the ground)."""
    if height is None or not np.isfinite(height).any():
        return 0.0
    lowest = float(np.nanmin(height))
    collective = np.sum(np.nan_to_num(speeds) ** 2, axis=1)
    spinning = flying & (collective > 0)
    if lowest > LANDED_HEIGHT_MAX_M or not spinning.any():
        return 0.0
    low = np.nan_to_num(height, nan=np.inf) <= lowest + GROUND_CONTACT_M
    resting = low & (collective < LANDED_COLLECTIVE * float(np.median(collective[spinning])))
    if resting.sum() < LANDED_MIN_ROWS:
        return 0.0
    return float(np.median(height[resting]))


def prepare_flight(log: FlightLog, vehicle: Vehicle, band: Band, name: str | None = None,
                   repeats: str = "samples", attitude: bool = False, gyro_bias: str = "off") -> Flight:
    """Build a Flight from a validated log. Raises UserError if nothing usable. What the
    vehicle file already models (gyro_scale, aero_damping, esc_delay_s) is applied here, so
    the base model includes it. `repeats`: "missing" treats copies of the previous row (per
    stream) as missing samples (evaluated, not the default: docs/gap.md), "samples" fuses them
    as measurements. `gyro_bias`: "attitude" removes the gyro's constant bias measured against
    the logged attitude before the torque (gyro_bias.py), "off" (the default) keeps the gyro."""
    if repeats not in REPEATS:
        raise UserError(f"repeats {repeats!r}: choose one of {', '.join(REPEATS)}")
    where = str(log.path) if log.path else (name or "log")
    if vehicle.inertia is None:
        raise UserError(f"{vehicle.path or 'vehicle'}: 'inertia' is null (the caller runs unit inertia)")
    # copies on the log's own rows, as the replay's --skip-repeats finds them (before the hold below)
    gyro_copy, rotor_copy = repeated_rows(log.gyro), repeated_rows(log.rotor_speed)
    speeds = _hold_rotor_rows(log.rotor_speed)
    has_gyro = np.any(np.isfinite(log.gyro), axis=1)
    if not has_gyro.all():
        # an events log: a gyro row's rotor speeds are the latest rotor row's (the hold above), and so is
        # whether they are a copy (the rows copy of the same samples flags that row)
        rotor_copy = _hold_rotor_rows(log.rotor_speed, rotor_copy, before=False)  # the flag of the row in force
        log = log.select(has_gyro)
        speeds = speeds[has_gyro]
        gyro_copy, rotor_copy = gyro_copy[has_gyro], rotor_copy[has_gyro]
    if len(log) < 10:
        raise UserError(f"{where}: fewer than 10 gyro samples")
    dt = np.diff(log.t)
    positive = dt[dt > 0]
    if positive.size == 0:
        raise UserError(f"{where}: the time never advances")
    dt_med = float(np.median(positive))
    rate = 1.0 / dt_med
    limit = absurd_speed_limit(speeds)
    speeds, repaired = clean_rotor_speeds(speeds, limit)
    speeds = _interp_missing(speeds)
    logged_speeds = speeds
    gyro = log.gyro
    # Rows whose torque or rotor speeds a copy leaves unmeasured: the rotor copies, and the rows beside
    # a gyro copy (their central difference uses it). Both sides of every fit are interpolated across
    # all of them with the same weights: interpolation is linear, so an interpolated torque still
    # equals the model at the interpolated speeds, where one side interpolated against the other
    # measured would read the interpolation's attenuation as a coefficient (+2-3 % on the synthetic
    # flights of test_gap_repeats.py).
    unmeasured = np.zeros(len(log), dtype=bool)
    if repeats == "missing" and (gyro_copy.any() or rotor_copy.any()):
        unmeasured = rotor_copy.copy()
        unmeasured[:-1] |= gyro_copy[1:]
        unmeasured[1:] |= gyro_copy[:-1]
        # the flying rows are still found on the speeds as logged (a held idle speed is no ramp)
        # interpolated as Omega^2, the model's input, so that the pair is matched term by term
        squared = np.array(speeds, dtype=float, copy=True) ** 2
        squared[unmeasured] = np.nan
        speeds = np.sqrt(np.maximum(_interp_missing(squared), 0.0))
        gyro = np.array(gyro, dtype=float, copy=True)
        gyro[gyro_copy] = np.nan
    speeds, held_fraction = unhold_rotor_stream(log.t, speeds)
    flying_speeds = logged_speeds if repeats == "missing" and rotor_copy.any() else speeds
    gyro = _interp_missing(gyro)
    if vehicle.gyro_scale is not None:
        gyro = gyro / np.asarray(vehicle.gyro_scale)[None, :]
    # flying: is_flying column, else every rotor spinning; off the ground where the height is
    # logged (contact up to GROUND_CONTACT_M above the landed height, landed_height)
    no_height = {k: v for k, v in log.extra.items() if k != "pz"}
    fly = flying_mask(FlightLog(t=log.t, gyro=gyro, rotor_speed=flying_speeds, extra=no_height, path=log.path))
    ground = 0.0
    if "pz" in log.extra:
        ground = landed_height(log.extra["pz"], flying_speeds, fly)
        fly &= np.nan_to_num(log.extra["pz"], nan=np.inf) > ground + GROUND_CONTACT_M
    uniform = np.ones(len(log), dtype=bool)
    bad_dt = np.abs(dt - dt_med) > 0.5 * dt_med
    uniform[1:] &= ~bad_dt
    uniform[:-1] &= ~bad_dt
    segs = segments(fly & uniform, min_length=int(max(MIN_SEGMENT_S * rate, 50)))
    if not segs:
        raise NoFlyingSegment(f"{where}: no flying segment of {MIN_SEGMENT_S:.0f} s or more with uniform timing")
    bias = {"applied": False, "value": None, "why": "--gyro-bias off"}
    if gyro_bias == "attitude":
        bias = gyro_bias_from_attitude(log.t, gyro, log.quat, np.concatenate([np.arange(a, b) for a, b in segs]))
        if bias["applied"]:
            gyro = gyro - np.asarray(bias["value"])[None, :]
    elif gyro_bias != "off":
        raise UserError(f"gyro_bias {gyro_bias!r}: choose one of {', '.join(GYRO_BIAS_MODES)}")
    inertia = np.asarray(vehicle.inertia, dtype=float)
    rate_dot = np.gradient(gyro, log.t, axis=0)
    torque = measured_torque(gyro, rate_dot, inertia)
    if unmeasured.any():
        torque[unmeasured] = np.nan
        torque = _interp_missing(torque)
    if vehicle.aero_damping is not None:
        torque = torque + gyro * np.asarray(vehicle.aero_damping)[None, :]  # the model's -D w moved to the left
    speed_dot = np.gradient(speeds, log.t, axis=0)
    acc = log.acc
    acc = _interp_missing(acc) if acc is not None and np.isfinite(acc).any() else None
    vel = log_body_velocity(log, missing=0.0)
    height = log.extra.get("pz")
    height = _interp_missing(height) if height is not None and np.isfinite(height).any() else None
    # the attitude, kept only for ground_effect at each hub's height (--ground-effect-height hub)
    quat = log.quat if attitude else None
    quat = _interp_missing(quat) if quat is not None and np.isfinite(quat).all(axis=1).any() else None
    logged_quat = log.quat if log.quat is not None and np.isfinite(log.quat).all(axis=1).any() else None
    logged_quat = _interp_missing(logged_quat) if logged_quat is not None else None
    cmd = log.group(tuple(f"cmd_{i + 1}" for i in range(log.rotor_count)))
    cmd = _interp_missing(cmd) if cmd is not None and np.isfinite(cmd).mean() > 0.5 else None
    vbat = log.extra.get("vbat")
    vbat = _interp_missing(vbat) if vbat is not None and np.isfinite(vbat).mean() > 0.5 else None
    flight = Flight(
        name=name or (log.path.stem if log.path else "log"), path=log.path, rate_hz=rate, t=log.t,
        gyro=gyro, rate_dot=rate_dot, speed=speeds, speed_dot=speed_dot, torque=torque,
        specific_force_z=None if acc is None else acc[:, 2], acc=acc, body_velocity=vel, height=height,
        cmd=cmd, vbat=vbat, segs=segs, band=band.for_rate(rate), repaired_rotor_samples=repaired,
        held_rotor_fraction=held_fraction, quat=quat, gyro_bias=bias,
        logged_quat=logged_quat, landed_height=ground)
    in_segments = np.concatenate([np.arange(a, b) for a, b in segs])
    flight.repeated_rows = {"gyro": repeated_row_stats(gyro_copy, in_segments),
                            "rotor": repeated_row_stats(rotor_copy, in_segments), "treated_as": repeats}
    block = max(int(round(BLOCK_S * rate)), 20)
    for a, b in segs:
        starts = list(range(a, b, block))
        for s in starts:
            e = min(s + block, b)
            if e - s >= block // 2 or not flight.blocks or flight.blocks[-1][1] != s:
                flight.blocks.append((s, e))
            else:  # a short tail joins the previous block
                flight.blocks[-1] = (flight.blocks[-1][0], e)
    if vehicle.esc_delay_s:
        flight.speed = flight.shifted(flight.speed, vehicle.esc_delay_s)
        flight.speed_dot = flight.shifted(flight.speed_dot, vehicle.esc_delay_s)
    return flight


def columns_present(logs: list[FlightLog], vehicle: Vehicle) -> dict[str, bool]:
    """Which optional inputs every log (and the vehicle) has."""
    def every(pred):
        return all(pred(log) for log in logs)

    return {
        "acc": every(lambda l: l.acc is not None and np.isfinite(l.acc).any()),
        "mass": vehicle.mass is not None,
        "inertia": vehicle.inertia is not None,
        "attitude": every(lambda l: l.quat is not None and np.isfinite(l.quat).any()),
        "velocity": every(lambda l: l.group(("vx", "vy", "vz")) is not None),
        "height": every(lambda l: "pz" in l.extra and np.isfinite(l.extra["pz"]).any()),
        "rotor_radius": vehicle.rotor_radius is not None,
        "cmd": every(lambda l: l.group(tuple(f"cmd_{i + 1}" for i in range(l.rotor_count))) is not None),
        "vbat": every(lambda l: "vbat" in l.extra and np.isfinite(l.extra["vbat"]).any()),
    }
