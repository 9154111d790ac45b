"""Flight-log interchange format v1: read, validate and write (CSV + vehicle JSON).

The format is specified in docs/flightlog.md: a CSV of samples (SI units,
body FLU, rotor speeds in rad/s) and a JSON description of the vehicle. Every
importer produces a FlightLog, every analysis consumes one.

Errors a user can fix (bad file, wrong units) raise propid.errors.UserError with
the file, line and column named.
"""

from __future__ import annotations

import io
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from propid.errors import UserError

GYRO_COLUMNS = ("gyro_x", "gyro_y", "gyro_z")
ACC_COLUMNS = ("acc_x", "acc_y", "acc_z")
QUAT_COLUMNS = ("qw", "qx", "qy", "qz")
VEL_COLUMNS = ("vx", "vy", "vz")
POS_COLUMNS = ("px", "py", "pz")

# Units sanity bounds. A gyro rarely measures more than 2000 deg/s = 34.9 rad/s; a
# propeller's typical speed (median while spinning) is below ~6000 rad/s (57,000 rpm,
# the fastest tiny brushless motors). Values beyond these mean the wrong unit.
GYRO_DEG_S_SUSPECT = 40.0  # rad/s, 99th percentile of |gyro|
ROTOR_RPM_SUSPECT = 8000.0  # rad/s, median of spinning rotor speeds
TIME_US_SUSPECT = 1.0e5  # s: a log longer than ~28 h is more likely in us or ms
# s: a median sample step this long (under 4 Hz) is more likely t in milliseconds (a 500 Hz
# log in ms steps by 2); no flight log this filter can use is sampled this slowly
SAMPLE_STEP_MS_SUSPECT = 0.25

_OMEGA_RE = re.compile(r"^omega_(\d+)$")
_CMD_RE = re.compile(r"^cmd_(\d+)$")
# An empty field: at the start of a line, between two commas, or at the end of a line.
_EMPTY_FIELD_RE = re.compile(r"(?<=,)(?=,|\r?$)|^(?=,)", re.MULTILINE)
_NAN_FIELD_RE = re.compile(r"(^|,)nan(?=,|$)", re.MULTILINE)


# --------------------------------------------------------------------------- vehicle
@dataclass
class Rotor:
    position: tuple[float, float, float]  # body FLU, relative to the centre of mass [m]
    yaw_sign: int  # sign of the yaw torque its drag puts on the body


@dataclass
class Vehicle:
    name: str
    rotors: list[Rotor]
    mass: float | None = None
    inertia: np.ndarray | None = None  # 3x3 [kg m^2]
    kf_nominal: list[float] | None = None  # per rotor [N/(rad/s)^2]
    km_nominal: list[float] | None = None  # per rotor [N m/(rad/s)^2]
    rotor_radius: float | None = None
    rotor_inertia: float | list[float] | None = None  # [kg m^2], one for all rotors or one per rotor
    # Optional extension keys (docs/flightlog.md): None means "not modelled".
    esc_delay_s: float | None = None  # logged rotor speed lags the gyro by this [s]; < 0: the gyro lags
    gyro_scale: list[float] | None = None  # gyro reads scale * true rate, per axis
    aero_damping: list[float] | None = None  # body torque -d_a * omega_a [N m s/rad]
    com_offset: list[float] | None = None  # CoM offset already applied to the rotor positions [m]
    loop_bandwidth_hz: float | None = None  # the attitude loop cancels body torques below this [Hz]
    # Airspeed terms of the rotor thrust (replay/thrust_aero.py): per rotor, d Omega v_z,b [N/(rad/s m/s)]
    # and c v_h^2 [N/(m/s)^2], body-frame velocity.
    thrust_climb_coeff: float | None = None
    thrust_translational_coeff: float | None = None
    notes: str = ""
    path: Path | None = None

    @property
    def rotor_count(self) -> int:
        return len(self.rotors)

    @property
    def positions(self) -> np.ndarray:
        return np.array([r.position for r in self.rotors], dtype=float)

    @property
    def yaw_signs(self) -> np.ndarray:
        return np.array([r.yaw_sign for r in self.rotors], dtype=float)

    @property
    def rotor_inertias(self) -> list[float] | None:
        """rotor_inertia per rotor [kg m^2], or None when not given."""
        if self.rotor_inertia is None:
            return None
        if isinstance(self.rotor_inertia, list):
            return list(self.rotor_inertia)
        return [float(self.rotor_inertia)] * self.rotor_count

    def to_json_dict(self) -> dict:
        inertia = None
        if self.inertia is not None:
            j = np.asarray(self.inertia)
            diagonal = np.allclose(j, np.diag(np.diag(j)))
            inertia = np.diag(j).tolist() if diagonal else j.reshape(-1).tolist()

        def per_rotor(values):
            if values is None:
                return None
            return values[0] if all(v == values[0] for v in values) else list(values)

        data = {
            "name": self.name,
            "mass": self.mass,
            "inertia": inertia,
            "rotors": [{"position": list(r.position), "yaw_sign": r.yaw_sign} for r in self.rotors],
            "kf_nominal": per_rotor(self.kf_nominal),
            "km_nominal": per_rotor(self.km_nominal),
            "rotor_radius": self.rotor_radius,
            "rotor_inertia": self.rotor_inertia,
            "notes": self.notes,
        }
        # Extension keys are written only when set, so a file without them reads back unchanged.
        for key in EXTENSION_KEYS:
            value = getattr(self, key)
            if value is not None:
                data[key] = list(value) if isinstance(value, (list, tuple)) else value
        return data


EXTENSION_KEYS = ("esc_delay_s", "gyro_scale", "aero_damping", "com_offset", "loop_bandwidth_hz",
                  "thrust_climb_coeff", "thrust_translational_coeff")


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _vector3_or_null(data: dict, key: str, where: str, unit: str, positive: bool = False,
                     non_negative: bool = False) -> list[float] | None:
    value = data.get(key)
    if value is None:
        return None
    ok = isinstance(value, list) and len(value) == 3 and all(_is_number(v) for v in value)
    if ok and positive:
        ok = all(v > 0 for v in value)
    if ok and non_negative:
        ok = all(v >= 0 for v in value)
    if not ok:
        need = "positive " if positive else ("non-negative " if non_negative else "finite ")
        raise UserError(f"{where}: '{key}' must be 3 {need}numbers{unit} or null, got {value!r}")
    return [float(v) for v in value]


def _positive_or_null(data: dict, key: str, where: str) -> float | None:
    value = data.get(key)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise UserError(f"{where}: '{key}' must be a positive number or null, got {value!r}")
    return float(value)


def _per_rotor_coeff(data: dict, key: str, count: int, where: str) -> list[float] | None:
    value = data.get(key)
    if value is None:
        return None
    values = value if isinstance(value, list) else [value] * count
    if len(values) != count:
        raise UserError(f"{where}: '{key}' has {len(values)} values but the vehicle has {count} rotors")
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise UserError(f"{where}: '{key}' values must be positive numbers, got {v!r}")
    return [float(v) for v in values]


def parse_vehicle(data: dict, where: str = "vehicle") -> Vehicle:
    """Validate a vehicle description (already decoded JSON) and return a Vehicle."""
    if not isinstance(data, dict):
        raise UserError(f"{where}: the top level must be a JSON object")
    rotors_raw = data.get("rotors")
    if not isinstance(rotors_raw, list) or not rotors_raw:
        raise UserError(f"{where}: 'rotors' must be a non-empty list")
    rotors = []
    for i, rotor in enumerate(rotors_raw, start=1):
        if not isinstance(rotor, dict):
            raise UserError(f"{where}: rotor {i} must be an object with 'position' and 'yaw_sign'")
        missing = [key for key in ("position", "yaw_sign") if key not in rotor]
        if missing:
            raise UserError(f"{where}: rotor {i} has no {' and no '.join(repr(k) for k in missing)}: each rotor needs "
                            "'position' (3 numbers, body FLU from the centre of mass [m]) and 'yaw_sign' (+1 or -1: "
                            "the sign of the z torque its drag puts on the body, docs/flightlog.md)")
        pos = rotor.get("position")
        if (
            not isinstance(pos, list)
            or len(pos) != 3
            or not all(isinstance(p, (int, float)) and not isinstance(p, bool) and math.isfinite(p) for p in pos)
        ):
            raise UserError(f"{where}: rotor {i} 'position' must be 3 finite numbers [m], got {pos!r}")
        sign = rotor.get("yaw_sign")
        if sign not in (1, -1) or isinstance(sign, bool):
            raise UserError(f"{where}: rotor {i} 'yaw_sign' must be +1 or -1, got {sign!r}")
        rotors.append(Rotor(tuple(float(p) for p in pos), int(sign)))
    inertia = data.get("inertia")
    if inertia is not None:
        flat = inertia if isinstance(inertia, list) else None
        if flat and all(isinstance(r, list) for r in flat):
            flat = [v for r in flat for v in r]
        if not flat or len(flat) not in (3, 9) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in flat
        ):
            raise UserError(f"{where}: 'inertia' must be [Jxx, Jyy, Jzz] or a 3x3 list [kg m^2], got {inertia!r}")
        j = np.diag(flat) if len(flat) == 3 else np.array(flat, dtype=float).reshape(3, 3)
        j = np.asarray(j, dtype=float)
        if not np.allclose(j, j.T) or np.any(np.linalg.eigvalsh(0.5 * (j + j.T)) <= 0):
            raise UserError(f"{where}: 'inertia' must be symmetric positive definite, got {inertia!r}")
        inertia = j
    name = data.get("name", "")
    return Vehicle(
        name=str(name),
        rotors=rotors,
        mass=_positive_or_null(data, "mass", where),
        inertia=inertia,
        kf_nominal=_per_rotor_coeff(data, "kf_nominal", len(rotors), where),
        km_nominal=_per_rotor_coeff(data, "km_nominal", len(rotors), where),
        rotor_radius=_positive_or_null(data, "rotor_radius", where),
        rotor_inertia=_rotor_inertia(data, len(rotors), where),
        esc_delay_s=_number_or_null(data, "esc_delay_s", where, limit=1.0),
        gyro_scale=_vector3_or_null(data, "gyro_scale", where, "", positive=True),
        aero_damping=_vector3_or_null(data, "aero_damping", where, " [N m s/rad]"),
        com_offset=_vector3_or_null(data, "com_offset", where, " [m]"),
        loop_bandwidth_hz=_positive_or_null(data, "loop_bandwidth_hz", where),
        thrust_climb_coeff=_number_or_null(data, "thrust_climb_coeff", where, limit=1.0),
        thrust_translational_coeff=_number_or_null(data, "thrust_translational_coeff", where, limit=1.0),
        notes=str(data.get("notes", "") or ""),
    )


def _number_or_null(data: dict, key: str, where: str, limit: float) -> float | None:
    value = data.get(key)
    if value is None:
        return None
    if not _is_number(value) or not -limit <= value <= limit:
        raise UserError(f"{where}: '{key}' must be a number within -{limit:g}..{limit:g} or null, got {value!r}")
    return float(value)


def _rotor_inertia(data: dict, count: int, where: str) -> float | list[float] | None:
    if isinstance(data.get("rotor_inertia"), list):
        return _per_rotor_coeff(data, "rotor_inertia", count, where)
    return _positive_or_null(data, "rotor_inertia", where)


def read_vehicle(path: str | Path) -> Vehicle:
    path = Path(path)
    try:
        raw = path.read_bytes()
    except IsADirectoryError:
        raise UserError(f"{path}: a directory, not a vehicle file") from None
    except OSError as exc:
        raise UserError(f"cannot read vehicle file {path}: {exc.strerror or exc}") from None
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise UserError(f"{path}: UTF-16 text; a vehicle file must be UTF-8 JSON (re-save it as UTF-8)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise UserError(f"{path}: not a UTF-8 text file (byte {exc.start}): a vehicle file is UTF-8 JSON") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise UserError(f"{path} line {exc.lineno}, column {exc.colno}: not valid JSON: {exc.msg}") from None
    vehicle = parse_vehicle(data, where=str(path))
    vehicle.path = path
    return vehicle


def write_vehicle(path: str | Path, vehicle: Vehicle) -> None:
    from propid.outputs import write_text

    write_text(path, json.dumps(vehicle.to_json_dict(), indent=2) + "\n")


def vehicle_path_for(log_path: str | Path) -> Path:
    """The vehicle file that sits beside a log: X.csv -> X.vehicle.json."""
    log_path = Path(log_path)
    return log_path.with_name(log_path.stem + ".vehicle.json")


def other_vehicle_files(log_path: str | Path) -> str:
    """For an error about a missing X.vehicle.json: the vehicle files that are in the log's folder under
    other names (one vehicle file for a folder of logs, as the shared real data has it), '' if none."""
    folder = Path(log_path).parent
    names = sorted(p.name for p in folder.glob("*.vehicle.json")) if folder.is_dir() else []
    if not names:
        return ""
    shown = ", ".join(str(folder / name) for name in names[:3]) + (", ..." if len(names) > 3 else "")
    return f"; the folder has {shown}: give it with --vehicle"


def run_name(log_path: str | Path) -> str:
    """A log's short name in tables: its file stem without a date token (_YYYYMMDD), which every log of one
    campaign shares (square_20251017_run1 -> square_run1)."""
    return re.sub(r"_(?:19|20)\d{2}(?:0[1-9]|1[0-2])(?:0[1-9]|[12]\d|3[01])(?=_|$)", "", Path(log_path).stem)


# --------------------------------------------------------------------------- samples
@dataclass
class FlightLog:
    """One flight in flight-log v1 units. Missing values are NaN."""

    t: np.ndarray  # (n,) [s]
    gyro: np.ndarray  # (n, 3) [rad/s], FLU, bias included
    rotor_speed: np.ndarray  # (n, N) [rad/s], vehicle rotor order
    extra: dict[str, np.ndarray] = field(default_factory=dict)  # every other column by name
    path: Path | None = None

    @property
    def rotor_count(self) -> int:
        return self.rotor_speed.shape[1]

    def __len__(self) -> int:
        return self.t.shape[0]

    def group(self, names: tuple[str, ...]) -> np.ndarray | None:
        """Columns `names` stacked as (n, k), or None if any is absent."""
        if all(n in self.extra for n in names):
            return np.column_stack([self.extra[n] for n in names])
        return None

    @property
    def acc(self) -> np.ndarray | None:
        return self.group(ACC_COLUMNS)

    @property
    def quat(self) -> np.ndarray | None:
        return self.group(QUAT_COLUMNS)

    def columns(self) -> dict[str, np.ndarray]:
        cols = {"t": self.t}
        for i, name in enumerate(GYRO_COLUMNS):
            cols[name] = self.gyro[:, i]
        for i in range(self.rotor_count):
            cols[f"omega_{i + 1}"] = self.rotor_speed[:, i]
        cols.update(self.extra)
        return cols

    def select(self, mask: np.ndarray) -> "FlightLog":
        return FlightLog(
            t=self.t[mask],
            gyro=self.gyro[mask],
            rotor_speed=self.rotor_speed[mask],
            extra={k: v[mask] for k, v in self.extra.items()},
            path=self.path,
        )


def _locate_bad_field(text: str, header: list[str], where: str) -> UserError:
    """Slow path, only after the fast parser failed: find the first bad line/field."""
    for lineno, line in enumerate(text.splitlines()[1:], start=2):
        if not line.strip():
            return UserError(f"{where} line {lineno}: empty line (every line after the header is one sample)")
        fields = line.split(",")
        if len(fields) != len(header):
            return UserError(
                f"{where} line {lineno}: {len(fields)} fields but the header names {len(header)} columns"
            )
        for name, value in zip(header, fields):
            value = value.strip()
            if value == "":
                continue
            try:
                float(value)
            except ValueError:
                return UserError(f"{where} line {lineno}, column {name}: {value!r} is not a number")
    return UserError(f"{where}: cannot parse the samples")


def _fill_empty_fields(body: str) -> str:
    """Every empty field -> 'nan' (what _EMPTY_FIELD_RE.sub("nan", body) does),
    with plain string replaces: the regex was most of reading a long log."""
    if "\r" in body:
        return _EMPTY_FIELD_RE.sub("nan", body)
    # ",,,": each pass fills every other empty field of a run, two fill them all.
    body = body.replace(",,", ",nan,").replace(",,", ",nan,")
    body = body.replace(",\n", ",nan\n").replace("\n,", "\nnan,")
    if body.endswith(","):
        body += "nan"
    if body.startswith(","):
        body = "nan" + body
    return body


def _parse_table(text: str, where: str) -> tuple[list[str], np.ndarray]:
    lines = text.split("\n", 1)
    if lines[0].startswith("H Product:Blackbox"):
        # a blackbox's header lines are text, so only its first line tells it from a CSV
        raise UserError(f"{where}: a Betaflight blackbox log, not a flight-log CSV: convert it first with "
                        "`propid convert`")
    header = [h.strip() for h in lines[0].strip().lstrip("\ufeff").split(",")]
    if header[0].startswith("#"):
        raise UserError(f"{where} line 1 starts with '#': flight-log v1 has no comment lines "
                        "(the first line names the columns)")
    if not header or header == [""]:
        raise UserError(f"{where} line 1: empty header (the first line must name the columns)")
    seen = set()
    for col, name in enumerate(header, start=1):
        if name == "":
            raise UserError(f"{where} line 1: column {col} has no name")
        if name in seen:
            raise UserError(f"{where} line 1: column {name} appears twice")
        seen.add(name)
    body = lines[1] if len(lines) > 1 else ""
    body = body.rstrip("\r\n")
    if not body.strip():
        return header, np.empty((0, len(header)))
    # Fast path: empty fields become 'nan', then numpy's C parser reads everything.
    filled = _fill_empty_fields(body)
    try:
        data = np.loadtxt(io.StringIO(filled), delimiter=",", dtype=float, ndmin=2, comments=None)
    except ValueError:
        raise _locate_bad_field(text, header, where) from None
    if data.shape[1] != len(header):
        raise _locate_bad_field(text, header, where)
    return header, data


def _first_bad_row(mask: np.ndarray) -> int:
    return int(np.flatnonzero(mask)[0])


def validate_columns(
    t: np.ndarray,
    gyro: np.ndarray,
    rotor_speed: np.ndarray,
    extra: dict[str, np.ndarray],
    where: str,
    line_offset: int = 2,
) -> None:
    """Check v1 semantics; raise UserError naming the line (row + line_offset) and column."""
    n = t.shape[0]
    if n == 0:
        raise UserError(f"{where}: no samples")
    if not np.all(np.isfinite(t)):
        row = _first_bad_row(~np.isfinite(t))
        raise UserError(f"{where} line {row + line_offset}, column t: time is missing (t may never be empty)")
    dt = np.diff(t)
    if np.any(dt < 0):
        row = _first_bad_row(dt < 0) + 1
        raise UserError(
            f"{where} line {row + line_offset}, column t: time goes backwards "
            f"({t[row - 1]:.6g} s -> {t[row]:.6g} s); rows must be in time order"
        )
    if t[-1] - t[0] > TIME_US_SUSPECT:
        raise UserError(
            f"{where}, column t: the log spans {t[-1] - t[0]:.3g} 's': t looks like milli- or microseconds, "
            "flight-log v1 wants seconds"
        )
    steps = dt[dt > 0]
    if steps.size and float(np.median(steps)) > SAMPLE_STEP_MS_SUSPECT:
        raise UserError(
            f"{where}, column t: samples are {float(np.median(steps)):.3g} 's' apart (median): t looks like "
            "milliseconds, flight-log v1 wants seconds"
        )
    for i, name in enumerate(GYRO_COLUMNS):
        bad = np.isinf(gyro[:, i])
        if np.any(bad):
            raise UserError(f"{where} line {_first_bad_row(bad) + line_offset}, column {name}: infinite value")
    finite_gyro = np.abs(gyro[np.isfinite(gyro)])
    if finite_gyro.size and np.percentile(finite_gyro, 99) > GYRO_DEG_S_SUSPECT:
        row, col = np.unravel_index(np.nanargmax(np.abs(np.where(np.isfinite(gyro), gyro, 0))), gyro.shape)
        raise UserError(
            f"{where} line {row + line_offset}, column {GYRO_COLUMNS[col]}: body rates up to "
            f"{gyro[row, col]:.4g} (99th percentile of |gyro| {np.percentile(finite_gyro, 99):.3g}) look like deg/s; "
            "flight-log v1 wants rad/s (multiply by pi/180)"
        )
    for i in range(rotor_speed.shape[1]):
        column = rotor_speed[:, i]
        name = f"omega_{i + 1}"
        bad = np.isinf(column)
        if np.any(bad):
            raise UserError(f"{where} line {_first_bad_row(bad) + line_offset}, column {name}: infinite value")
        neg = column < 0
        if np.any(neg):
            raise UserError(
                f"{where} line {_first_bad_row(neg) + line_offset}, column {name}: negative rotor speed "
                f"{column[neg][0]:.6g}; rotor speeds are positive magnitudes in rad/s"
            )
    spinning = rotor_speed[np.isfinite(rotor_speed) & (rotor_speed > 0)]
    if spinning.size and np.median(spinning) > ROTOR_RPM_SUSPECT:
        raise UserError(
            f"{where}, columns omega_*: median rotor speed {np.median(spinning):.6g} while spinning looks like "
            "RPM or eRPM, flight-log v1 wants rad/s (rpm * 2*pi/60; eRPM / pole pairs first)"
        )
    acc = np.column_stack([extra[c] for c in ACC_COLUMNS]) if all(c in extra for c in ACC_COLUMNS) else None
    if acc is not None:
        norm = np.linalg.norm(acc, axis=1)
        norm = norm[np.isfinite(norm)]
        if norm.size:
            med = float(np.median(norm))
            if 0.3 < med < 3.0:
                raise UserError(
                    f"{where}, columns acc_*: median |acc| {med:.3g} looks like g, flight-log v1 wants m/s^2 (* 9.80665)"
                )
            if med > 200.0:
                raise UserError(
                    f"{where}, columns acc_*: median |acc| {med:.4g} looks like raw sensor counts, "
                    "flight-log v1 wants m/s^2"
                )


def flightlog_from_columns(
    columns: dict[str, np.ndarray],
    where: str,
    rotor_count: int | None = None,
    line_offset: int = 2,
) -> FlightLog:
    """Build and validate a FlightLog from named columns (flight-log v1 names)."""
    names = list(columns)
    missing = [c for c in ("t",) + GYRO_COLUMNS if c not in columns]
    if missing:
        raise UserError(f"{where} line 1: required column(s) {', '.join(missing)} missing")
    omega_idx = sorted(int(m.group(1)) for m in (_OMEGA_RE.match(n) for n in names) if m)
    if not omega_idx:
        raise UserError(f"{where} line 1: no rotor speed columns omega_1..omega_N")
    count = max(omega_idx)
    if omega_idx != list(range(1, count + 1)):
        gaps = sorted(set(range(1, count + 1)) - set(omega_idx))
        raise UserError(f"{where} line 1: rotor speed columns must be omega_1..omega_{count}; missing "
                        + ", ".join(f"omega_{i}" for i in gaps))
    if rotor_count is not None and count != rotor_count:
        raise UserError(
            f"{where} line 1: the log has {count} rotor speed columns (omega_1..omega_{count}) "
            f"but the vehicle file has {rotor_count} rotors"
        )
    t = np.asarray(columns["t"], dtype=float)
    gyro = np.column_stack([np.asarray(columns[c], dtype=float) for c in GYRO_COLUMNS])
    rotor_speed = np.column_stack([np.asarray(columns[f"omega_{i}"], dtype=float) for i in range(1, count + 1)])
    skip = {"t", *GYRO_COLUMNS, *(f"omega_{i}" for i in range(1, count + 1))}
    extra = {n: np.asarray(columns[n], dtype=float) for n in names if n not in skip}
    validate_columns(t, gyro, rotor_speed, extra, where, line_offset=line_offset)
    return FlightLog(t=t, gyro=gyro, rotor_speed=rotor_speed, extra=extra)


def _read_text(path: Path, what: str) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise UserError(f"{path}: not a text CSV file (is it a binary log? try `propid convert`)") from None
    except IsADirectoryError:
        raise UserError(f"{path}: a directory, not a {what}") from None
    except OSError as exc:
        raise UserError(f"cannot read {what} {path}: {exc.strerror or exc}") from None


def read_table(path: str | Path, require_rows: bool = True) -> dict[str, np.ndarray]:
    """Any CSV of this format's syntax (header of unique names, numbers, empty = missing)
    as {column: float array}, without the flight-log v1 semantics: the reader for files
    that carry more than a flight log (SITL logs with estimates and truth, `propid log
    --csv` estimates). UserError naming the line and column on anything malformed."""
    path = Path(path)
    header, data = _parse_table(_read_text(path, "CSV file"), str(path))
    if require_rows and data.shape[0] == 0:
        raise UserError(f"{path}: header only, no samples")
    return {name: data[:, i] for i, name in enumerate(header)}


def read_flightlog(path: str | Path, vehicle: Vehicle | None = None) -> FlightLog:
    """Read and validate a flight-log v1 CSV. With `vehicle`, the rotor count must match."""
    path = Path(path)
    columns = read_table(path, require_rows=False)
    log = flightlog_from_columns(columns, str(path), None if vehicle is None else vehicle.rotor_count)
    log.path = path
    return log


# The time column keeps this much resolution whatever its origin: nine significant digits hold
# 1 us only up to t = 1000 s, so a log stamped from 1e6 s at 500 Hz would come back with repeated times.
TIME_RESOLUTION_S = 1e-7


def _time_format(t: np.ndarray) -> str:
    """The shortest %g format (9..17 significant digits) that writes every time to TIME_RESOLUTION_S."""
    for digits in range(9, 18):
        fmt = f"%.{digits}g"
        back = np.array([float(fmt % v) for v in t])
        if np.all(np.abs(back - t) <= TIME_RESOLUTION_S):
            return fmt
    return "%.17g"


def write_flightlog(path: str | Path, log: FlightLog) -> None:
    """Write a FlightLog as flight-log v1 CSV (missing values as empty fields)."""
    cols = log.columns()
    names = list(cols)
    matrix = np.column_stack([np.asarray(cols[n], dtype=float) for n in names])
    buffer = io.StringIO()
    formats = ["%.9g"] * len(names)
    formats[names.index("t")] = _time_format(matrix[:, names.index("t")])
    np.savetxt(buffer, matrix, delimiter=",", fmt=formats)
    body = buffer.getvalue()
    # numpy writes NaN as 'nan'; the spec prefers an empty field for a missing value.
    body = _NAN_FIELD_RE.sub(r"\1", body)
    from propid.outputs import write_text

    write_text(path, ",".join(names) + "\n" + body)
