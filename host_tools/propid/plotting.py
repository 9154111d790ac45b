"""Flight plots: coefficient estimates with +-1 sigma bands (and truth when the log
has it), gyro biases, rotor speeds and body rates, drawn to PNG with matplotlib's
Agg backend (no display needed).

Two sources give the same picture:
- a CSV with the SITL flight log's column names (t, est_kf_i, std_kf_i, true_kf_i,
  omega_i, gyro_x..., docs/flightlog.md), which is also what `propid log --csv`
  writes for the estimates;
- a .tlog recorded from propid telemetry (PROPID_* + ESC_STATUS + HIGHRES_IMU).

All series are SI, body FLU (MAVLink FRD values are converted back on reading).
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from propid.errors import UserError
from propid.outputs import save_figure
from propid.units import FRD_TO_FLU

# Files bigger than this get a progress bar while they are read.
PROGRESS_BYTES = 4 << 20

_AXES = ("x", "y", "z")


@dataclass
class Series:
    """Columns (name -> 1-D float array) sharing one time vector t."""

    t: np.ndarray
    columns: dict[str, np.ndarray] = field(default_factory=dict)

    def has(self, name: str) -> bool:
        return name in self.columns and bool(np.any(np.isfinite(self.columns[name])))

    def get(self, name: str) -> np.ndarray:
        return self.columns[name]


@dataclass
class FlightData:
    """What a log holds, grouped by time base (telemetry streams have their own rates)."""

    source: Path
    rotor_count: int
    estimates: Series | None = None   # est_kf_i, std_kf_i, est_km_i, ..., est_bg_*, std_bg_*
    truth: Series | None = None       # true_kf_i, true_km_i, true_bg_*
    rotors: Series | None = None      # omega_i [rad/s]
    rates: Series | None = None       # gyro_x..z (measured) and/or true_wx..z [rad/s]
    context: dict = field(default_factory=dict)  # vehicle, trajectory, effects when known


# --------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------
def read_csv_columns(path: Path, progress: bool | None = None) -> dict[str, np.ndarray]:
    """A CSV with a header line -> name -> float array (empty = NaN), by the one CSV reader
    (propid.flightlog.read_table). `progress` is accepted for compatibility; the C parser
    needs no bar."""
    from propid.flightlog import read_table

    return read_table(path)


def _count_rotors(names, prefix: str) -> int:
    pattern = re.compile(rf"^{re.escape(prefix)}(\d+)$")
    indices = sorted(int(m.group(1)) for n in names if (m := pattern.match(n)))
    count = 0
    while count < len(indices) and indices[count] == count + 1:
        count += 1
    return count


def _series(t: np.ndarray, columns: dict[str, np.ndarray], names) -> Series | None:
    picked = {n: columns[n] for n in names if n in columns}
    if not picked:
        return None
    return Series(t=t, columns=picked)


def _flight_from_columns(path: Path, columns: dict[str, np.ndarray]) -> FlightData:
    if "t" not in columns:
        raise UserError(f"{path}: no 't' column (is this a propid flight log?)")
    t = columns["t"]
    if t.size > 1 and np.any(np.diff(t[np.isfinite(t)]) < 0):
        raise UserError(f"{path}: column t decreases: samples out of order")
    names = list(columns)
    rotor_count = max(_count_rotors(names, "est_kf_"), _count_rotors(names, "omega_"),
                      _count_rotors(names, "true_kf_"))
    if rotor_count == 0:
        raise UserError(f"{path}: no est_kf_i, true_kf_i or omega_i columns: nothing to plot")
    est_names, true_names = [], []
    for i in range(1, rotor_count + 1):
        est_names += [f"est_kf_{i}", f"std_kf_{i}", f"est_km_{i}", f"std_km_{i}"]
        true_names += [f"true_kf_{i}", f"true_km_{i}"]
    for a in _AXES:
        est_names += [f"est_bg_{a}", f"std_bg_{a}"]
        true_names += [f"true_bg_{a}"]
    rate_names = [f"gyro_{a}" for a in _AXES] + [f"true_w{a}" for a in _AXES] + \
                 [f"est_w{a}" for a in _AXES]
    return FlightData(
        source=path, rotor_count=rotor_count,
        estimates=_series(t, columns, est_names),
        truth=_series(t, columns, true_names),
        rotors=_series(t, columns, [f"omega_{i}" for i in range(1, rotor_count + 1)]),
        rates=_series(t, columns, rate_names))


def _flight_from_tlog(path: Path, progress: bool | None) -> FlightData:
    from propid import mavlink_io
    from propid.importers.tlog import read_tlog_streams

    if progress is None:
        progress = path.stat().st_size > PROGRESS_BYTES
    streams = read_tlog_streams(path, estimates=True, progress=progress)
    rotor_count = streams.estimate_rotor_count or streams.esc_count()
    if rotor_count == 0:
        raise UserError(f"{path}: no PROPID_COEFFICIENTS or ESC_STATUS messages: nothing to plot")
    flight = FlightData(source=path, rotor_count=rotor_count)
    if streams.estimates:
        names = mavlink_io.estimate_columns(rotor_count)
        t = np.array([r["t"] for r in streams.estimates])
        flight.estimates = Series(t=t, columns={
            n: np.array([float(r.get(n, math.nan)) for r in streams.estimates])
            for n in names if n != "t"})
    if streams.esc:
        times = sorted(streams.esc)
        flight.rotors = Series(t=np.array(times) * 1e-6, columns={
            f"omega_{k + 1}": np.array([streams.esc[t].get(k, math.nan) for t in times])
            for k in range(rotor_count)})
    if streams.imu:
        imu = np.array(sorted(streams.imu, key=lambda r: r[0]), dtype=float)
        flight.rates = Series(t=imu[:, 0] * 1e-6, columns={
            f"gyro_{a}": imu[:, 1 + i] * FRD_TO_FLU[i] for i, a in enumerate(_AXES)})
    return flight


def load_flight(path: str | os.PathLike, progress: bool | None = None) -> FlightData:
    """Read a .csv (SITL flight log or `propid log --csv`) or a .tlog."""
    path = Path(path)
    if not path.exists():
        raise UserError(f"{path}: no such file")
    if not path.is_file():
        raise UserError(f"{path}: not a regular file")
    suffix = path.suffix.lower()
    if suffix == ".tlog":
        return _flight_from_tlog(path, progress)
    if suffix == ".csv":
        flight = _flight_from_columns(path, read_csv_columns(path, progress))
        flight.context = run_context(path)
        return flight
    raise UserError(f"{path}: unknown log type '{suffix}' (expected .tlog or .csv)")


def run_context(log_path: Path, summary_path: Path | None = None) -> dict:
    """What flew: the vehicle name from X.vehicle.json beside the log X.csv, and the
    trajectory, effects and mode from the simulator's summary (given, or X.summary.json
    beside the log). Only files that belong to this log by name are read; unreadable ones
    are ignored (the plot is still useful without its title)."""
    import json

    context: dict = {}
    vehicle_file = log_path.with_name(log_path.stem + ".vehicle.json")
    if vehicle_file.is_file():
        from propid.flightlog import read_vehicle

        try:
            context["vehicle"] = read_vehicle(vehicle_file).name or vehicle_file.name
        except UserError:
            pass
    summary_path = summary_path or log_path.with_name(log_path.stem + ".summary.json")
    if summary_path.is_file():
        try:
            summary = json.loads(summary_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            summary = {}
        if isinstance(summary, dict):
            for key in ("vehicle", "trajectory", "effects", "mode"):
                if isinstance(summary.get(key), str) and summary[key]:
                    context.setdefault(key, summary[key])
    return context


def context_title(name: str, context: dict) -> str:
    parts = [name]
    for key in ("vehicle", "trajectory", "mode"):
        if context.get(key):
            parts.append(f"{key} {context[key]}")
    if "effects" in context:
        parts.append(f"effects {context['effects'] or 'none'}")
    return ", ".join(parts)


def broken_at_gaps(t: np.ndarray, *ys: np.ndarray, factor: float = 5.0):
    """(t, *ys) with a NaN row inserted wherever a time step exceeds `factor` x the median
    step, so a line is not drawn across a skipped segment."""
    t = np.asarray(t, dtype=float)
    if t.size < 3:
        return (t, *ys)
    steps = np.diff(t)
    positive = steps[steps > 0]
    if positive.size == 0:
        return (t, *ys)
    gaps = np.flatnonzero(steps > factor * float(np.median(positive))) + 1
    if gaps.size == 0:
        return (t, *ys)
    out_t = np.insert(t, gaps, np.nan)
    return (out_t, *(np.insert(np.asarray(y, dtype=float), gaps, np.nan, axis=0) for y in ys))


def add_truth(flight: FlightData, truth_source: FlightData) -> None:
    """Overlay the truth of another log (e.g. the SITL CSV beside a recorded tlog)."""
    if truth_source.truth is None:
        raise UserError(f"{truth_source.source}: no true_kf_i / true_km_i columns")
    flight.truth = truth_source.truth


# --------------------------------------------------------------------------
# Drawing
# --------------------------------------------------------------------------
def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _band(ax, t, mean, std, color, label):
    if std is None:
        t, mean = broken_at_gaps(t, mean)
    else:
        t, mean, std = broken_at_gaps(t, mean, std)
    ax.plot(t, mean, color=color, lw=1.2, label=label)
    if std is not None and np.any(np.isfinite(std)):
        ax.fill_between(t, mean - std, mean + std, color=color, alpha=0.2, lw=0)


def _line(ax, t, y, **style):
    ax.plot(*broken_at_gaps(t, y), **style)


# Body-rate sources a log may hold, how each is drawn and what it is.
RATE_SOURCES = (
    ("gyro_", "-", "gyro (measured, bias included)"),
    ("true_w", "--", "truth (simulator)"),
    ("est_w", ":", "filter estimate"),
)


def plot_flight(flight: FlightData, out: str | os.PathLike, title: str | None = None,
                dpi: int = 110) -> Path:
    """Draw the Figure-2-like overview to a PNG; returns its path."""
    plt = _pyplot()
    out = Path(out)
    panels = []
    est, truth = flight.estimates, flight.truth
    if est is not None and est.has("est_kf_1"):
        panels += ["kf", "km"]
    if est is not None and est.has("est_bg_x"):
        panels.append("bias")
    if flight.rotors is not None:
        panels.append("rotors")
    if flight.rates is not None:
        panels.append("rates")
    if not panels:
        raise UserError(f"{flight.source}: no estimates, rotor speeds or body rates to plot")

    fig, axes = plt.subplots(len(panels), 1, figsize=(10, 2.6 * len(panels) + 0.8),
                             sharex=True, squeeze=False)
    axes = axes[:, 0]
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    n = flight.rotor_count
    for ax, panel in zip(axes, panels):
        if panel in ("kf", "km"):
            for i in range(1, n + 1):
                c = colors[(i - 1) % len(colors)]
                mean = est.get(f"est_{panel}_{i}")
                std = est.columns.get(f"std_{panel}_{i}")
                _band(ax, est.t, mean, std, c, f"rotor {i}")
                if truth is not None and truth.has(f"true_{panel}_{i}"):
                    _line(ax, truth.t, truth.get(f"true_{panel}_{i}"), color=c, ls="--", lw=1.0)
            unit = "N/(rad/s)$^2$" if panel == "kf" else "N m/(rad/s)$^2$"
            name = "thrust coeff. $k_f$" if panel == "kf" else "drag coeff. $k_m$"
            ax.set_ylabel(f"{name}\n[{unit}]")
            ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 3))
        elif panel == "bias":
            for k, a in enumerate(_AXES):
                c = colors[k]
                _band(ax, est.t, est.get(f"est_bg_{a}"), est.columns.get(f"std_bg_{a}"), c,
                      f"$b_{{g,{a}}}$")
                if truth is not None and truth.has(f"true_bg_{a}"):
                    _line(ax, truth.t, truth.get(f"true_bg_{a}"), color=c, ls="--", lw=1.0)
            ax.set_ylabel("gyro bias\n[rad/s]")
        elif panel == "rotors":
            for i in range(1, n + 1):
                name = f"omega_{i}"
                if name in flight.rotors.columns:
                    _line(ax, flight.rotors.t, flight.rotors.get(name),
                          color=colors[(i - 1) % len(colors)], lw=0.8, label=f"rotor {i}")
            ax.set_ylabel("rotor speed\n[rad/s]")
        elif panel == "rates":
            rates = flight.rates
            drawn = [(prefix, ls, what) for prefix, ls, what in RATE_SOURCES
                     if rates.has(f"{prefix}x" if prefix != "gyro_" else "gyro_x")]
            for prefix, ls, what in drawn:
                for k, a in enumerate(_AXES):
                    name = f"{prefix}{a}"
                    if name in rates.columns:
                        _line(ax, rates.t, rates.get(name), color=colors[k], lw=0.8, ls=ls,
                              label=f"$\\omega_{a}$ {what}" if len(drawn) > 1 else f"$\\omega_{a}$")
            what = " / ".join(w for _, _, w in drawn) or "none"
            ax.set_ylabel("body rate (FLU)\n[rad/s]")
            ax.set_title(f"body rate: {what}", fontsize=8, loc="left")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize=7, ncol=min(n, 4))
    axes[-1].set_xlabel("time [s]")
    heading = title or context_title(flight.source.name, flight.context)
    if truth is not None:
        heading += "  (dashed: truth, bands: $\\pm1\\sigma$)"
    elif est is not None:
        heading += "  (bands: $\\pm1\\sigma$)"
    fig.suptitle(heading, fontsize=10)
    fig.tight_layout()
    try:
        save_figure(fig, out, dpi=dpi)
    finally:
        plt.close(fig)
    return out


# --------------------------------------------------------------------------
# Replays (propid.replay results)
# --------------------------------------------------------------------------
def plot_replay(result, path: str, title: str = "", reference_kf: float | None = None, dpi: int = 80) -> None:
    """PNG: kf and km per rotor with +-1 sigma bands, gyro biases, over time."""
    plt = _pyplot()

    s = result.series
    fig, axes = plt.subplots(3, 1, figsize=(7.5, 7.0), sharex=True, dpi=dpi)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, key, label in ((axes[0], "kf", "kf"), (axes[1], "km", "km")):
        for k in range(s[key].shape[1]):
            c = colors[k % len(colors)]
            t, mean, std = broken_at_gaps(s["t"], s[key][:, k], s[f"{key}_std"][:, k])
            ax.plot(t, mean, color=c, lw=1.0, label=f"rotor {k + 1}")
            ax.fill_between(t, mean - std, mean + std, color=c, alpha=0.15, lw=0)
        nominal = result.summary["config"]["thrust_coeff_nominal" if key == "kf" else "drag_coeff_nominal"]
        ax.axhline(float(np.mean(nominal)), color="k", ls=":", lw=1, label="prior mean")
        ax.set_ylabel(f"{label} [{result.summary['units'][key].split(':')[0]}]")
        ax.grid(alpha=0.3)
    if reference_kf is not None:
        axes[0].axhline(reference_kf, color="r", ls="--", lw=1, label="independent (thrust)")
    axes[0].legend(fontsize=7, ncol=3, loc="lower right")
    for k, axis in enumerate("xyz"):
        c = colors[k]
        t, mean, std = broken_at_gaps(s["t"], s["gyro_bias"][:, k], s["gyro_bias_std"][:, k])
        axes[2].plot(t, mean, color=c, lw=1.0, label=f"b_{axis}")
        axes[2].fill_between(t, mean - std, mean + std, color=c, alpha=0.15, lw=0)
    axes[2].set_ylabel("gyro bias [rad/s]")
    axes[2].set_xlabel("log time [s]")
    axes[2].legend(fontsize=7, ncol=3, loc="upper right")  # a fixed place: "best" searches every point (slow, warns)
    axes[2].grid(alpha=0.3)
    if title:
        axes[0].set_title(title, fontsize=9)
    fig.tight_layout()
    try:
        save_figure(fig, path)
    finally:
        plt.close(fig)

def plot_fleet(summaries: list[dict], path: str, reference_kf: float, dpi: int = 80) -> None:
    """Bar chart per run: the filter's kf and the least-squares checks, relative to the
    independent kf."""
    from propid.flightlog import run_name

    plt = _pyplot()

    names = [run_name(s["log"]) if s.get("log") else "?" for s in summaries]
    series = {"filter (mean of rotors)": [np.mean(s["kf_mean"]) / reference_kf for s in summaries]}

    def check(band, key):
        return [((s.get("checks") or {}).get("bands", {}).get(band, {}).get(key, {}) or {}).get("kf", np.nan)
                / reference_kf for s in summaries]

    if all(s.get("checks") for s in summaries):
        series["LS thrust from acc_z"] = check("raw", "thrust_kf")
        series["LS torque raw (roll+pitch)/2"] = list(0.5 * (np.array(check("raw", "roll_kf")) + np.array(check("raw", "pitch_kf"))))
        series["LS torque 2-10 Hz (roll+pitch)/2"] = list(
            0.5 * (np.array(check("2-10Hz", "roll_kf")) + np.array(check("2-10Hz", "pitch_kf"))))
    fig, ax = plt.subplots(figsize=(9, 3.6), dpi=dpi)
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
    try:
        save_figure(fig, path)
    finally:
        plt.close(fig)

