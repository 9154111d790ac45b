"""Flight plots: coefficient estimates with +-1 sigma bands (and truth when the log
has it), gyro biases, rotor speeds and body rates, drawn to PNG with matplotlib's
Agg backend (no display needed).

Two sources give the same picture:
- a CSV with the SITL flight log's column names (t, est_kf_i, std_kf_i, true_kf_i,
  omega_i, gyro_x..., see TEAM.md contract 4), which is also what `propid log --csv`
  writes for the estimates;
- a .tlog recorded from propid telemetry (PROPID_* + ESC_STATUS + HIGHRES_IMU).

All series are SI, body FLU (MAVLink FRD values are converted back on reading).
"""

from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from propid.errors import UserError

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


# --------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------
def _parse_float(text: str) -> float:
    text = text.strip()
    if text == "":
        return math.nan
    return float(text)


def read_csv_columns(path: Path, progress: bool | None = None) -> dict[str, np.ndarray]:
    """A CSV with a header line -> name -> float array (empty or 'nan' = NaN).
    UserError with the line number on anything malformed."""
    size = path.stat().st_size
    if size == 0:
        raise UserError(f"{path}: empty file")
    if progress is None:
        progress = size > PROGRESS_BYTES
    try:
        handle = open(path, newline="", encoding="utf-8")
    except OSError as exc:
        raise UserError(f"{path}: cannot open: {exc}") from exc
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=size, unit="B", unit_scale=True, desc=path.name, leave=False,
                   disable=None)  # None: no bar when stderr is not a terminal

    def counted_lines():
        for line in handle:
            if bar is not None:
                bar.update(len(line))
            yield line

    with handle:
        try:
            reader = csv.reader(counted_lines())
            header = next(reader, None)
            if not header or not any(h.strip() for h in header):
                raise UserError(f"{path}: no header line")
            names = [h.strip() for h in header]
            if len(set(names)) != len(names):
                raise UserError(f"{path}: duplicate column names in the header")
            rows: list[list[float]] = []
            for line_number, record in enumerate(reader, start=2):
                if not record:
                    continue
                if len(record) != len(names):
                    raise UserError(f"{path}:{line_number}: {len(record)} fields, header has "
                                    f"{len(names)} (truncated or corrupt file?)")
                try:
                    rows.append([_parse_float(v) for v in record])
                except ValueError as exc:
                    raise UserError(f"{path}:{line_number}: not a number: {exc}") from exc
        except UnicodeDecodeError as exc:
            raise UserError(f"{path}: not a text CSV file ({exc.reason})") from exc
        except csv.Error as exc:
            raise UserError(f"{path}: malformed CSV: {exc}") from exc
        finally:
            if bar is not None:
                bar.close()
    if not rows:
        raise UserError(f"{path}: header only, no samples")
    data = np.asarray(rows, dtype=float)
    return {name: data[:, i] for i, name in enumerate(names)}


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

    if progress is None:
        progress = path.stat().st_size > PROGRESS_BYTES
    assembler = mavlink_io.EstimateRows()
    estimate_rows: list[dict] = []
    rotor_t: list[float] = []
    rotor_rows: dict[int, list[float]] = {}
    rate_t: list[float] = []
    rate_rows: list[list[float]] = []
    esc_latest: dict[int, float] = {}
    wanted = {mavlink_io.MSG_COEFFICIENTS, mavlink_io.MSG_GYRO, mavlink_io.MSG_STATUS,
              "ESC_STATUS", "HIGHRES_IMU"}
    for msg in mavlink_io.read_tlog(path, types=wanted, progress=progress):
        kind = msg.get_type()
        if kind == "ESC_STATUS":
            # One message per 4 ESCs: a sample is complete when the first block arrives again.
            for k, rpm in enumerate(msg.rpm):
                esc_latest[msg.index + k] = mavlink_io.rpm_to_rad_s(rpm)
            if msg.index == 0:
                rotor_t.append(msg.time_usec * 1e-6)
                for k in range(8):
                    rotor_rows.setdefault(k, []).append(esc_latest.get(k, math.nan))
        elif kind == "HIGHRES_IMU":
            rate_t.append(msg.time_usec * 1e-6)
            rate_rows.append(mavlink_io.frd_to_flu((msg.xgyro, msg.ygyro, msg.zgyro)))
        else:
            row = assembler.feed(msg)
            if row is not None:
                estimate_rows.append(row)
    rotor_count = assembler.rotor_count or 0
    if rotor_count == 0:
        # No estimates: count the ESCs that ever reported a speed.
        rotor_count = sum(1 for k, v in rotor_rows.items() if np.any(np.asarray(v) > 0))
    if rotor_count == 0:
        raise UserError(f"{path}: no PROPID_COEFFICIENTS or ESC_STATUS messages: nothing to plot")
    flight = FlightData(source=path, rotor_count=rotor_count)
    if estimate_rows:
        names = mavlink_io.estimate_columns(rotor_count)
        t = np.array([r["t"] for r in estimate_rows])
        flight.estimates = Series(t=t, columns={
            n: np.array([float(r.get(n, math.nan)) for r in estimate_rows])
            for n in names if n != "t"})
    if rotor_t:
        flight.rotors = Series(t=np.array(rotor_t), columns={
            f"omega_{k + 1}": np.array(rotor_rows[k]) for k in range(rotor_count)})
    if rate_t:
        rates = np.array(rate_rows)
        flight.rates = Series(t=np.array(rate_t), columns={
            f"gyro_{a}": rates[:, i] for i, a in enumerate(_AXES)})
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
        return _flight_from_columns(path, read_csv_columns(path, progress))
    raise UserError(f"{path}: unknown log type '{suffix}' (expected .tlog or .csv)")


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
    ax.plot(t, mean, color=color, lw=1.2, label=label)
    if std is not None and np.any(np.isfinite(std)):
        ax.fill_between(t, mean - std, mean + std, color=color, alpha=0.2, lw=0)


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
                    ax.plot(truth.t, truth.get(f"true_{panel}_{i}"), color=c, ls="--", lw=1.0)
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
                    ax.plot(truth.t, truth.get(f"true_bg_{a}"), color=c, ls="--", lw=1.0)
            ax.set_ylabel("gyro bias\n[rad/s]")
        elif panel == "rotors":
            for i in range(1, n + 1):
                name = f"omega_{i}"
                if name in flight.rotors.columns:
                    ax.plot(flight.rotors.t, flight.rotors.get(name),
                            color=colors[(i - 1) % len(colors)], lw=0.8, label=f"rotor {i}")
            ax.set_ylabel("rotor speed\n[rad/s]")
        elif panel == "rates":
            rates = flight.rates
            source = "gyro" if rates.has("gyro_x") else ("true_w" if rates.has("true_wx") else "est_w")
            for k, a in enumerate(_AXES):
                name = f"gyro_{a}" if source == "gyro" else f"{source}{a}"
                if name in rates.columns:
                    ax.plot(rates.t, rates.get(name), color=colors[k], lw=0.8,
                            label=f"$\\omega_{a}$")
            ax.set_ylabel("body rate (FLU)\n[rad/s]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize=7, ncol=min(n, 4))
    axes[-1].set_xlabel("time [s]")
    heading = title or flight.source.name
    if truth is not None:
        heading += "  (dashed: truth, bands: $\\pm1\\sigma$)"
    elif est is not None:
        heading += "  (bands: $\\pm1\\sigma$)"
    fig.suptitle(heading, fontsize=10)
    fig.tight_layout()
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=dpi)
    except OSError as exc:
        raise UserError(f"cannot write {out}: {exc}") from exc
    finally:
        plt.close(fig)
    return out
