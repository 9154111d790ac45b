"""Table 1 of Folk & Spinos: per-flight metrics from SITL logs, aggregation, rendering.

Definitions (docs/results.md states them with their numbers):

- Tracking RMSE per axis over the whole logged flight: sqrt(mean((p - p_ref)^2)) [m];
  yaw: ZYX yaw of the attitude quaternion minus ``ref_yaw``, wrapped to [-180, 180) deg.
- Convergence time of a group of estimates (all kf and km together; all gyro biases
  together): the first logged time after which EVERY later estimate of the group stays
  within ``threshold`` of its truth, where threshold = 0.1 x the filter's initial
  (prior) standard deviation of that state; coefficients relative to their nominal
  value, biases in rad/s. The SITL (sitl/metrics.c) uses the same band. Every
  campaign sets the prior to the standard deviation of the distribution the truth is
  drawn from (truth = nominal x U(1 - s, 1 + s): relative std s / sqrt(3); bias
  U(-b, b): std b / sqrt(3)), so this is the paper's "within 0.1 standard deviation
  of the true value". A flight whose last sample is still
  outside never converged: its time is None; the aggregate counts such flights and
  uses the flight duration for them in the mean (the worst value a flight of that
  length can show, so the mean is a lower bound on the true mean).
- Stable: the simulator did not stop the flight for divergence, the log covers the
  whole duration with finite values, the position error stays below
  ``max_position_error`` (1 m) plus the largest single-sample jump of the reference
  (the step trajectory's commanded step; 0 for smooth references) and the vehicle
  stays upright (body z up) throughout.
- Aggregates average over the stable flights only, as the paper does.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from propid.errors import UserError
from propid.outputs import save_figure

TRAJECTORIES = ("lissajous", "circle", "step")
MODES = ("oracle", "incorrect", "filter")

# (key, header, decimals) in the paper's column order.
METRICS = (
    ("rmse_x", "x (m)", 3),
    ("rmse_y", "y (m)", 3),
    ("rmse_z", "z (m)", 3),
    ("rmse_yaw_deg", "yaw (deg)", 3),
    ("t_conv_coeff_s", "kf & km (s)", 3),
    ("t_conv_bias_s", "b_g (s)", 3),
    ("stable_pct", "% stable", 0),
)

# Table 1 of the paper, transcribed: rmse x, y, z [m], yaw [deg], t_conv kf&km, b_g [s], % stable.
PAPER_TABLE1: dict[str, dict[str, dict[str, float]]] = {}
_PAPER_ROWS = {
    ("lissajous", "oracle"): (0.064, 0.063, 0.005, 1.535, 0.278, 1.955, 100),
    ("lissajous", "incorrect"): (0.158, 0.161, 0.076, 11.569, 0.180, 1.968, 90),
    ("lissajous", "filter"): (0.064, 0.062, 0.012, 12.020, 0.288, 2.038, 80),
    ("circle", "oracle"): (0.047, 0.045, 0.001, 0.600, 0.083, 3.057, 100),
    ("circle", "incorrect"): (0.215, 0.152, 0.075, 17.383, 0.223, 2.611, 100),
    ("circle", "filter"): (0.056, 0.054, 0.013, 28.442, 0.172, 2.426, 100),
    ("step", "oracle"): (0.230, 0.000, 0.001, 0.000, 0.019, 9.539, 100),
    ("step", "incorrect"): (0.325, 0.121, 0.067, 16.168, 0.044, 9.395, 100),
    ("step", "filter"): (0.308, 0.088, 0.159, 26.371, 0.051, 8.232, 100),
}
for (_traj, _mode), _values in _PAPER_ROWS.items():
    PAPER_TABLE1.setdefault(_traj, {})[_mode] = {
        key: float(value) for (key, _, _), value in zip(METRICS, _values)
    }


CONVERGENCE_FRACTION = 0.1  # of the prior std: the band of every convergence time


@dataclass(frozen=True)
class ConvergenceSpec:
    """Bands of the convergence times: 0.1 x the filter's prior std of each state."""

    coeff_threshold_rel: float  # |est - true| / nominal for every kf and km
    bias_threshold: float  # |est - true| [rad/s] for every gyro bias axis
    # Sensitivity check only (extra *_loose_s keys): the same definition with a band
    # this many times wider (10 -> one full prior std).
    loose_factor: float = 10.0

    @classmethod
    def from_prior_std(cls, coeff_rel_std: float, bias_std: float) -> "ConvergenceSpec":
        """The band from the filter's prior stds, read as float32 as the filter (and
        the SITL's own metrics) hold them."""
        if not (coeff_rel_std > 0 and bias_std > 0):
            raise UserError("convergence bands need positive prior standard deviations")
        return cls(
            coeff_threshold_rel=CONVERGENCE_FRACTION * float(np.float32(coeff_rel_std)),
            bias_threshold=CONVERGENCE_FRACTION * float(np.float32(bias_std)),
        )

    @classmethod
    def from_uniform_truth(cls, coeff_spread: float, gyro_bias_max: float) -> "ConvergenceSpec":
        """Priors equal to the truth distribution's std: kf, km = nominal x U(1-s, 1+s),
        biases U(-b, b) (std = half-width / sqrt(3))."""
        if coeff_spread <= 0 or gyro_bias_max <= 0:
            raise UserError("convergence thresholds need a positive spread and bias range")
        return cls.from_prior_std(coeff_spread / math.sqrt(3.0), gyro_bias_max / math.sqrt(3.0))


# --------------------------------------------------------------------------- reading
def read_log_columns(path: str | Path) -> dict[str, np.ndarray]:
    """A SITL log CSV (flight log v1 + SITL columns) as {column: float array}."""
    from propid.flightlog import read_table

    return read_table(path)


def rotor_count(columns: dict[str, np.ndarray]) -> int:
    count = 0
    while f"omega_{count + 1}" in columns:
        count += 1
    return count


def read_nominal_coefficients(vehicle_json: str | Path, count: int) -> tuple[np.ndarray, np.ndarray]:
    """kf_nominal, km_nominal per rotor from a vehicle file (propid.flightlog.read_vehicle)."""
    from propid.flightlog import read_vehicle

    vehicle = read_vehicle(vehicle_json)
    if vehicle.rotor_count != count:
        raise UserError(f"{vehicle_json}: {vehicle.rotor_count} rotors, the log has {count}")
    for key, values in (("kf_nominal", vehicle.kf_nominal), ("km_nominal", vehicle.km_nominal)):
        if values is None:
            raise UserError(f"{vehicle_json}: {key} must be a positive number or a list of {count}")
    return np.asarray(vehicle.kf_nominal, dtype=float), np.asarray(vehicle.km_nominal, dtype=float)


# --------------------------------------------------------------------------- metrics
def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Wrap radians to [-pi, pi)."""
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi


def yaw_from_quaternion(qw, qx, qy, qz) -> np.ndarray:
    """ZYX yaw [rad] of body->world quaternions."""
    return np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def convergence_time(t: np.ndarray, outside: np.ndarray) -> float | None:
    """First time after which ``outside`` is False for every later sample.

    ``outside[k]`` is True when at least one estimate of the group is outside its
    threshold at t[k]. Returns t[0] when never outside, None when still outside at
    the last sample (never converged).
    """
    outside = np.asarray(outside, dtype=bool)
    if outside.size == 0:
        return None
    if outside[-1]:
        return None
    bad = np.flatnonzero(outside)
    if bad.size == 0:
        return float(t[0])
    return float(t[bad[-1] + 1])


def _require(columns: dict[str, np.ndarray], names: list[str], where: str) -> None:
    missing = [name for name in names if name not in columns]
    if missing:
        raise UserError(f"{where}: missing column(s) {', '.join(missing[:6])}"
                        + (" ..." if len(missing) > 6 else ""))


def trial_metrics(columns: dict[str, np.ndarray], kf_nominal: np.ndarray,
                  km_nominal: np.ndarray, spec: ConvergenceSpec, *,
                  duration_s: float | None = None, diverged: bool = False,
                  max_position_error: float = 1.0, where: str = "log") -> dict:
    """Metrics of one flight (see the module docstring for the definitions)."""
    n_rotors = rotor_count(columns)
    base = ["t", "px", "py", "pz", "ref_px", "ref_py", "ref_pz", "ref_yaw",
            "qw", "qx", "qy", "qz", "true_bg_x", "true_bg_y", "true_bg_z",
            "est_bg_x", "est_bg_y", "est_bg_z"]
    per_rotor = [f"{kind}_{c}_{i}" for kind in ("true", "est") for c in ("kf", "km")
                 for i in range(1, n_rotors + 1)]
    _require(columns, base + per_rotor, where)
    if n_rotors == 0:
        raise UserError(f"{where}: no omega_1.. columns")
    kf_nominal = np.asarray(kf_nominal, dtype=float)
    km_nominal = np.asarray(km_nominal, dtype=float)
    if kf_nominal.shape != (n_rotors,) or km_nominal.shape != (n_rotors,):
        raise UserError(f"{where}: {n_rotors} rotors but nominal coefficients for "
                        f"{kf_nominal.size}/{km_nominal.size}")

    t = columns["t"]
    err = {axis: columns[f"p{axis}"] - columns[f"ref_p{axis}"] for axis in "xyz"}
    yaw = yaw_from_quaternion(columns["qw"], columns["qx"], columns["qy"], columns["qz"])
    yaw_err = wrap_angle(yaw - columns["ref_yaw"])

    coeff_err = []
    for i in range(1, n_rotors + 1):
        coeff_err.append(np.abs(columns[f"est_kf_{i}"] - columns[f"true_kf_{i}"]) / kf_nominal[i - 1])
        coeff_err.append(np.abs(columns[f"est_km_{i}"] - columns[f"true_km_{i}"]) / km_nominal[i - 1])
    coeff_outside = np.any(~(np.vstack(coeff_err) <= spec.coeff_threshold_rel), axis=0)
    bias_err = np.vstack([np.abs(columns[f"est_bg_{a}"] - columns[f"true_bg_{a}"]) for a in "xyz"])
    bias_outside = np.any(~(bias_err <= spec.bias_threshold), axis=0)
    coeff_outside_loose = np.any(
        ~(np.vstack(coeff_err) <= spec.loose_factor * spec.coeff_threshold_rel), axis=0)
    bias_outside_loose = np.any(~(bias_err <= spec.loose_factor * spec.bias_threshold), axis=0)

    distance = np.sqrt(err["x"] ** 2 + err["y"] ** 2 + err["z"] ** 2)
    # A commanded step (the step trajectory) puts the reference its own size away
    # at once: allow the largest single-sample reference jump on top of the bound.
    ref = np.vstack([columns["ref_px"], columns["ref_py"], columns["ref_pz"]])
    jumps = np.sqrt(np.sum(np.diff(ref, axis=1) ** 2, axis=0)) if t.size > 1 else np.zeros(1)
    largest_jump = float(np.max(jumps)) if jumps.size else 0.0
    allowance = largest_jump if largest_jump > 0.05 else 0.0
    body_z_up = 1.0 - 2.0 * (columns["qx"] ** 2 + columns["qy"] ** 2)  # world z of body z
    reasons = []
    if diverged:
        reasons.append("simulator stopped the flight (diverged)")
    if not np.all(np.isfinite(distance)) or not np.all(np.isfinite(body_z_up)):
        reasons.append("non-finite state")
    else:
        if np.max(distance) >= max_position_error + allowance:
            reasons.append(f"position error reached {np.max(distance):.2f} m"
                           + (f" (step of {allowance:.2f} m allowed)" if allowance else ""))
        if np.min(body_z_up) <= 0.0:
            reasons.append("tilted beyond 90 deg")
    if duration_s is not None and t[-1] < duration_s - 0.01:
        reasons.append(f"log ends at {t[-1]:.3f} s of {duration_s:g} s")

    def rmse(values: np.ndarray) -> float:
        return float(np.sqrt(np.mean(values ** 2)))

    return {
        "rmse_x": rmse(err["x"]),
        "rmse_y": rmse(err["y"]),
        "rmse_z": rmse(err["z"]),
        "rmse_yaw_deg": math.degrees(rmse(yaw_err)),
        "t_conv_coeff_s": convergence_time(t, coeff_outside),
        "t_conv_bias_s": convergence_time(t, bias_outside),
        "t_conv_coeff_loose_s": convergence_time(t, coeff_outside_loose),
        "t_conv_bias_loose_s": convergence_time(t, bias_outside_loose),
        "final_coeff_err_rel_max": float(np.max(np.vstack(coeff_err)[:, -1])),
        "final_bias_err_max": float(np.max(bias_err[:, -1])),
        "max_position_error": float(np.nanmax(distance)) if np.any(np.isfinite(distance)) else None,
        "stable": not reasons,
        "unstable_reason": "; ".join(reasons),
        "duration_s": float(t[-1]),
    }


CONVERGENCE_KEYS = ("t_conv_coeff_s", "t_conv_bias_s", "t_conv_coeff_loose_s", "t_conv_bias_loose_s",
                    "t_bound_coeff_s", "t_bound_bias_s", "t_bound3_coeff_s", "t_bound3_bias_s")


def aggregate(trials: list[dict], duration_s: float) -> dict:
    """Average the stable trials' metrics as Table 1 does (see module docstring)."""
    stable = [trial for trial in trials if trial["stable"]]
    out: dict = {"trials": len(trials), "stable_trials": len(stable),
                 "stable_pct": 100.0 * len(stable) / len(trials) if trials else 0.0}
    for key in ("rmse_x", "rmse_y", "rmse_z", "rmse_yaw_deg"):
        values = np.array([trial[key] for trial in stable], dtype=float)
        out[key] = float(np.mean(values)) if values.size else None
        out[f"{key}_std"] = float(np.std(values)) if values.size else None
    for key in CONVERGENCE_KEYS:
        if key.startswith("t_bound") and not any(key in trial for trial in stable):
            continue  # campaign without the Cramér-Rao bound
        raw = [trial.get(key) for trial in stable]
        censored = np.array([duration_s if value is None else value for value in raw], dtype=float)
        out[key] = float(np.mean(censored)) if censored.size else None
        out[f"{key}_std"] = float(np.std(censored)) if censored.size else None
        out[f"{key}_unconverged"] = sum(1 for value in raw if value is None)
    return out


# --------------------------------------------------------------------------- rendering
def load_table(path: str | Path) -> dict:
    path = Path(path)
    try:
        table = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise UserError(f"{path}: not a text file (a Table 1 file is the JSON `propid campaign` writes)") from None
    except OSError as exc:
        raise UserError(f"{path}: cannot read ({exc.strerror})") from None
    except json.JSONDecodeError as exc:
        raise UserError(f"{path}: not JSON ({exc.msg} at line {exc.lineno})") from None
    if not isinstance(table, dict) or not any(traj in table for traj in TRAJECTORIES):
        raise UserError(f"{path}: not a Table 1 file (no lissajous/circle/step entries)")
    for traj in TRAJECTORIES:
        for mode, row in (table.get(traj) or {}).items():
            if not isinstance(row, dict):
                raise UserError(f"{path}: {traj}/{mode} is not an object")
    return table


def _cell(value, decimals: int) -> str:
    if value is None:
        return "—"
    return f"{value:.{decimals}f}"


def table_rows(table: dict, with_paper: bool = True) -> list[list[str]]:
    """Header + one row per (trajectory, mode) present; cells 'ours (paper)'."""
    rows = [["trajectory", "mode"] + [header for _, header, _ in METRICS] + ["trials"]]
    for traj in TRAJECTORIES:
        for mode in MODES:
            row = (table.get(traj) or {}).get(mode)
            if row is None:
                continue
            paper = PAPER_TABLE1[traj][mode]
            cells = [traj.capitalize(), mode.capitalize()]
            for key, _, decimals in METRICS:
                text = _cell(row.get(key), decimals)
                unconverged = row.get(f"{key}_unconverged")
                if unconverged:
                    text += f"* ({unconverged})"
                if with_paper:
                    text += f" ({_cell(paper[key], decimals)})"
                cells.append(text)
            cells.append(str(row.get("trials", "")))
            rows.append(cells)
    return rows


def render_markdown(table: dict, with_paper: bool = True) -> str:
    rows = table_rows(table, with_paper)
    lines = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(rows[0])]
    lines += ["| " + " | ".join(row) + " |" for row in rows[1:]]
    notes = []
    if with_paper:
        notes.append("Each cell: ours (paper's Table 1).")
    notes.append("Averages over the stable flights. Convergence: first time after which every "
                 "later estimate stays within 0.1 x the filter's prior std (= the truth "
                 "distribution's std) of the truth.")
    if any("*" in cell for row in rows[1:] for cell in row):
        notes.append("`*` (n): n stable flights never converged; each counts as the full "
                     "flight duration in the mean.")
    return "\n".join(lines) + "\n\n" + "\n".join(notes) + "\n"


def bound_rows(table: dict) -> list[list[str]]:
    """Header + one row per cell that has Cramér-Rao times: filter vs bound."""
    rows = [["trajectory", "mode", "kf & km: filter (s)", "bound (s)", "3-sigma bound (s)",
             "filter / bound", "b_g: filter (s)", "bound (s)", "3-sigma bound (s)", "filter / bound"]]

    def timed(row, key):
        text = _cell(row.get(key), 3)
        unconverged = row.get(f"{key}_unconverged")
        return text + (f"* ({unconverged})" if unconverged else "")

    def ratio(row, filt, bound):
        if row.get(filt) is None or not row.get(bound):
            return "—"
        stable = row.get("stable_trials")
        if stable and row.get(f"{filt}_unconverged") == stable == row.get(f"{bound}_unconverged"):
            return "—"  # neither reached on any flight: both are the flight duration, their ratio says nothing
        return f"{row[filt] / row[bound]:.2f}"
    for traj in TRAJECTORIES:
        for mode in MODES:
            row = (table.get(traj) or {}).get(mode)
            if row is None or row.get("t_bound_coeff_s") is None:
                continue
            rows.append([traj.capitalize(), mode.capitalize(),
                         timed(row, "t_conv_coeff_s"), timed(row, "t_bound_coeff_s"),
                         timed(row, "t_bound3_coeff_s"),
                         ratio(row, "t_conv_coeff_s", "t_bound_coeff_s"),
                         timed(row, "t_conv_bias_s"), timed(row, "t_bound_bias_s"),
                         timed(row, "t_bound3_bias_s"),
                         ratio(row, "t_conv_bias_s", "t_bound_bias_s")])
    return rows


def render_bound_markdown(table: dict) -> str:
    """The filter's convergence times next to the Cramér-Rao bound's ('' without them)."""
    rows = bound_rows(table)
    if len(rows) == 1:
        return ""
    lines = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(rows[0])]
    lines += ["| " + " | ".join(row) + " |" for row in rows[1:]]
    return ("\n".join(lines) + "\n\nBound (s): first time after which the Cramér-Rao bound's "
            "std of every state of the group stays within the convergence band (0.1 x prior "
            "std); 3-sigma: three bound stds within the band. Mean over the stable flights; "
            "`*` (n): n flights where it is never reached (counted as the flight duration).\n")


def render_png(table: dict, path: str | Path, with_paper: bool = True) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = table_rows(table, with_paper)
    fig, ax = plt.subplots(figsize=(16, 0.32 * len(rows) + 0.6))
    ax.axis("off")
    grid = ax.table(cellText=rows[1:], colLabels=rows[0], loc="center", cellLoc="center")
    grid.auto_set_font_size(False)
    grid.set_fontsize(8)
    grid.scale(1.0, 1.4)
    title = "Table 1: ours (paper)" if with_paper else "Table 1"
    ax.set_title(title)
    fig.tight_layout()
    try:
        save_figure(fig, path, dpi=150)
    finally:
        plt.close(fig)
