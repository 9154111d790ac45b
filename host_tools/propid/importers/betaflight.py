"""Betaflight blackbox (.bbl/.bfl) -> flight-log v1.

Decoding uses the PyPI package `orangebox`; the unit and frame conversion is a separate
function on a plain field table (name -> numpy column) so it can be tested without a
binary log.

Conventions (docs/real-data.md has the evidence):
- t        = (time - time[0]) * 1e-6                         [us -> s]
- gyro     = gyroADC * pi/180 (/10 with blackbox_high_resolution)  [deg/s -> rad/s]
  Betaflight's body axes are x forward, y left, z up for the gyro (roll + = right side
  down, pitch + = nose down, yaw + = nose left), i.e. FLU: no sign change.
- omega_i  = eRPM[m] * 100 / (motor_poles / 2) * 2*pi/60     [eRPM/100 -> rad/s]
  with m the Betaflight motor that sits where the vehicle file's rotor i is.
- acc      = accSmooth / acc_1G * 9.80665                     [counts -> m/s^2]
- cmd_i    = (motor[m] - 48) / 1999 for DShot (0 stop .. 1 full), else scaled by motorOutput
- vbat     = vbatLatest * 0.01 V; current = amperageLatest * 0.01 A (scale unverified)
- extras   gyro_unfilt_x/y/z [rad/s], setpoint_x/y/z [rad/s], rc_throttle [0..1]
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle, flightlog_from_columns
from propid.importers.motor_order import BETAFLIGHT_QUADX, quadrant_map
from propid.units import erpm_to_rad_s_factor

GRAVITY = 9.80665
DSHOT_MIN = 48  # DShot command values 48..2047 are throttle 0..1
DSHOT_MAX = 2047
# Betaflight's motor_pwm_protocol enum: 5..8 are DSHOT150/300/600 and PROSHOT1000.
DSHOT_PROTOCOLS = {5, 6, 7, 8}


def _header_number(headers: dict, key: str, default=None):
    value = headers.get(key, default)
    if isinstance(value, (list, tuple)):
        return value
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return default
    return value


def convert_betaflight(
    headers: dict,
    fields: dict[str, np.ndarray],
    vehicle: Vehicle | None = None,
    motor_map: list[int] | None = None,
    where: str = "betaflight log",
) -> tuple[FlightLog, dict]:
    """Convert decoded blackbox main frames (field name -> column) to a FlightLog.

    Returns the log and a dict describing the conversion (motor map, scales)."""
    required = ["time", "gyroADC[0]", "gyroADC[1]", "gyroADC[2]"]
    missing = [f for f in required if f not in fields]
    if missing:
        raise UserError(f"{where}: blackbox fields {', '.join(missing)} missing (is gyro logging disabled?)")
    motor_count = sum(1 for k in fields if k.startswith("motor["))
    erpm_names = [f"eRPM[{i}]" for i in range(motor_count)]
    if motor_count == 0 or not all(n in fields for n in erpm_names):
        raise UserError(
            f"{where}: no eRPM fields: the log has no rotor speeds. Enable bidirectional DShot "
            "(dshot_bidir = ON) and keep the RPM field in the blackbox (Betaflight 4.3+: "
            "blackbox 'RPM' field not disabled), then log again"
        )
    poles = _header_number(headers, "motor_poles")
    if poles is None or not isinstance(poles, (int, float)) or poles < 2 or int(poles) % 2:
        raise UserError(f"{where}: header motor_poles = {poles!r}: need the motor's (even) pole count to convert eRPM")
    pole_pairs = int(poles) // 2
    acc_1g = _header_number(headers, "acc_1G")
    high_res = bool(_header_number(headers, "blackbox_high_resolution", 0) or 0)
    rate_scale = 0.1 if high_res else 1.0  # high-resolution logs store deg/s * 10

    if motor_map is None:
        motor_map, map_note = quadrant_map(vehicle, BETAFLIGHT_QUADX, motor_count)
    else:
        if len(motor_map) != motor_count:
            raise UserError(f"{where}: motor map has {len(motor_map)} entries, the log has {motor_count} motors")
        map_note = "given: vehicle rotor i <- motor " + ",".join(str(m + 1) for m in motor_map)

    time_us = np.asarray(fields["time"], dtype=float)
    deg = math.pi / 180.0
    columns: dict[str, np.ndarray] = {"t": (time_us - time_us[0]) * 1e-6}
    for axis, name in enumerate("xyz"):
        columns[f"gyro_{name}"] = np.asarray(fields[f"gyroADC[{axis}]"], dtype=float) * rate_scale * deg
    erpm_to_rad_s = erpm_to_rad_s_factor(pole_pairs, erpm_scale=100.0)  # the log stores eRPM/100
    for rotor, motor in enumerate(motor_map, start=1):
        columns[f"omega_{rotor}"] = np.asarray(fields[f"eRPM[{motor}]"], dtype=float) * erpm_to_rad_s
    if acc_1g and all(f"accSmooth[{a}]" in fields for a in range(3)):
        for axis, name in enumerate("xyz"):
            columns[f"acc_{name}"] = np.asarray(fields[f"accSmooth[{axis}]"], dtype=float) / float(acc_1g) * GRAVITY
    protocol = _header_number(headers, "motor_pwm_protocol")
    output = _header_number(headers, "motorOutput")
    if protocol in DSHOT_PROTOCOLS:
        cmd_low, cmd_high = DSHOT_MIN, DSHOT_MAX
    elif isinstance(output, (list, tuple)) and len(output) == 2:
        cmd_low, cmd_high = float(output[0]), float(output[1])
    else:
        cmd_low = cmd_high = None
    if cmd_low is not None:
        for rotor, motor in enumerate(motor_map, start=1):
            columns[f"cmd_{rotor}"] = (np.asarray(fields[f"motor[{motor}]"], dtype=float) - cmd_low) / (cmd_high - cmd_low)
    if "vbatLatest" in fields:
        columns["vbat"] = np.asarray(fields["vbatLatest"], dtype=float) * 0.01
    if "amperageLatest" in fields:
        columns["current"] = np.asarray(fields["amperageLatest"], dtype=float) * 0.01
    if all(f"gyroUnfilt[{a}]" in fields for a in range(3)):
        for axis, name in enumerate("xyz"):
            columns[f"gyro_unfilt_{name}"] = np.asarray(fields[f"gyroUnfilt[{axis}]"], dtype=float) * rate_scale * deg
    if all(f"setpoint[{a}]" in fields for a in range(3)):
        for axis, name in enumerate("xyz"):
            columns[f"setpoint_{name}"] = np.asarray(fields[f"setpoint[{axis}]"], dtype=float) * rate_scale * deg
    if "rcCommand[3]" in fields:
        columns["rc_throttle"] = (np.asarray(fields["rcCommand[3]"], dtype=float) - 1000.0) / 1000.0
    log = flightlog_from_columns(columns, where, None if vehicle is None else vehicle.rotor_count)
    info = {
        "format": "betaflight",
        "motor_poles": int(poles),
        "erpm_to_rad_s": erpm_to_rad_s,
        "high_resolution": high_res,
        "motor_map": [m + 1 for m in motor_map],
        "motor_map_note": map_note,
        "frame": "Betaflight gyro axes taken as FLU (no sign change)",
    }
    return log, info


def decode_blackbox(
    path: str | Path, log_index: int | None = None, progress: bool = False
) -> tuple[dict, dict[str, np.ndarray], dict]:
    """Decode main frames of log `log_index` (1-based, as Betaflight's explorer counts;
    None: the first) of a .bbl/.bfl file with orangebox: (headers, field table, info).
    info lists every log of the file with its size, so a caller can say which was taken."""
    try:
        from orangebox import Parser
    except ImportError:  # pragma: no cover - dependency of the package
        raise UserError("reading Betaflight logs needs the Python package 'orangebox' (pip install orangebox)") from None
    path = Path(path)
    if not path.is_file():
        raise UserError(f"cannot read {path}: no such file")
    with open(path, "rb") as handle:
        if not handle.read(18).startswith(b"H Product:Blackbox"):
            raise UserError(f"{path}: not a Betaflight blackbox log (no 'H Product:Blackbox' header)")
    logging.getLogger("orangebox").setLevel(logging.ERROR)
    try:
        parser = Parser.load(str(path), 1)
    except Exception as exc:  # orangebox raises assorted errors on foreign files
        raise UserError(f"{path}: not a readable Betaflight blackbox log ({exc})") from None
    try:
        return _decode_log(parser, path, log_index, progress)
    except UserError:
        raise
    except Exception as exc:  # orangebox trusts the headers: a corrupt one fails anywhere
        raise UserError(f"{path}: corrupt Betaflight blackbox log ({type(exc).__name__}: {exc})") from None


def _decode_log(parser, path: Path, log_index: int | None, progress: bool) -> tuple[dict, dict[str, np.ndarray], dict]:
    count = parser.reader.log_count
    pointers = list(parser.reader.log_pointers) + [path.stat().st_size]
    logs = [{"index": k + 1, "bytes": int(pointers[k + 1] - pointers[k])} for k in range(count)]
    log_index = 1 if log_index is None else log_index
    if not 1 <= log_index <= count:
        raise UserError(f"{path}: --log-index {log_index} out of range: the file holds {count} log(s), numbered 1..{count}")
    if log_index != 1:
        parser.set_log_index(log_index)
    names = parser.field_names
    wanted = [i for i, n in enumerate(names) if n.split("[")[0] in _WANTED_BASES]
    rows = []
    frames = parser.frames()
    if progress:
        from tqdm import tqdm

        frames = tqdm(frames, desc=f"{path.name} log {log_index}", unit="frame", mininterval=0.5, leave=False)
    try:
        for frame in frames:
            data = frame.data
            rows.append([data[i] for i in wanted])
    except Exception as exc:  # orangebox: RuntimeError on a truncated file, others on corrupt bytes
        if not rows:
            # orangebox fails on missing headers with internal errors (e.g. a TypeError on a None field count)
            raise UserError(f"{path} log {log_index}: no data frame could be decoded: the log ends in or right "
                            f"after its headers, or they are corrupt (orangebox: {type(exc).__name__}: {exc})") from None
        # a truncated or partly corrupt file (power cut): keep the frames decoded so far
    finally:
        if progress:
            frames.close()
    if not rows:
        raise UserError(f"{path} log {log_index}: no data frames")
    table = np.array(rows, dtype=float)
    fields = {names[i]: table[:, j] for j, i in enumerate(wanted)}
    headers = dict(parser.headers)
    events = [e.type.name for e in parser.events]
    info = {"log_index": log_index, "log_count": count, "logs": logs, "frames": len(rows), "events": events,
            "firmware": headers.get("Firmware revision")}
    return headers, fields, info


_WANTED_BASES = {
    "loopIteration", "time", "gyroADC", "gyroUnfilt", "accSmooth", "motor", "eRPM",
    "vbatLatest", "amperageLatest", "setpoint", "rcCommand",
}


def import_betaflight(
    path: str | Path,
    vehicle: Vehicle | None = None,
    log_index: int | None = None,
    motor_map: list[int] | None = None,
    progress: bool = False,
) -> tuple[FlightLog, dict]:
    headers, fields, decode_info = decode_blackbox(path, log_index, progress)
    log, info = convert_betaflight(headers, fields, vehicle, motor_map, where=f"{path} log {decode_info['log_index']}")
    info.update(decode_info)
    return log, info
