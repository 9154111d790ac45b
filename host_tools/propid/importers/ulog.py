"""PX4 ULog (.ulg) -> flight-log v1, decoded with the PyPI package `pyulog`.

Topics read:
- gyro: `sensor_combined.gyro_rad[0..2]` (calibrated, bias included, as the filter wants),
  or `vehicle_angular_velocity.xyz[0..2]` with --gyro-topic (bias already removed by EKF2);
- accelerometer: `sensor_combined.accelerometer_m_s2[0..2]` when present;
- rotor speeds: `esc_status.esc[i].esc_rpm` [rpm, mechanical; sign dropped].

PX4 is FRD (x forward, y right, z down): v_FLU = (x, -y, -z) for gyro and accelerometer.
ESC i is PX4's motor i+1; quad X motors are matched to the vehicle file's rotors by
quadrant (PX4 quad X: 1 front-right, 2 rear-left, 3 front-left, 4 rear-right).

The streams have their own timestamps and rates, so the output is event-style: one row
per gyro sample (omega_* empty) and one per ESC report (gyro_* empty), merged in time
order, t = (timestamp - first timestamp) * 1e-6. `propid replay` pushes each stream at
its own times.
"""

from __future__ import annotations

import contextlib
import io
import sys
from pathlib import Path

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle, flightlog_from_columns
from propid.importers.motor_order import PX4_QUADX, quadrant_map
from propid.units import FRD_TO_FLU, RPM_TO_RAD_S

GYRO_TOPICS = {
    "sensor_combined": "gyro_rad[{}]",
    "vehicle_angular_velocity": "xyz[{}]",
}


def merge_streams(
    gyro_time_us: np.ndarray,
    gyro_columns: dict[str, np.ndarray],
    rotor_time_us: np.ndarray,
    rotor_columns: dict[str, np.ndarray],
) -> dict[str, np.ndarray]:
    """Event-style merge of two timed streams into one table (NaN where a stream has no
    sample). At equal times the rotor row comes first, so a replay predicts with it."""
    start = min(gyro_time_us[0], rotor_time_us[0])
    times = np.concatenate([rotor_time_us, gyro_time_us]).astype(np.int64)
    # stable sort on (time, stream) with rotor rows (0) before gyro rows (1)
    stream = np.concatenate([np.zeros(rotor_time_us.size, np.int8), np.ones(gyro_time_us.size, np.int8)])
    order = np.lexsort((stream, times))
    n_rot = rotor_time_us.size
    out = {"t": (times[order] - start) * 1e-6}
    for name, col in rotor_columns.items():
        merged = np.concatenate([col, np.full(gyro_time_us.size, np.nan)])
        out[name] = merged[order]
    for name, col in gyro_columns.items():
        merged = np.concatenate([np.full(n_rot, np.nan), col])
        out[name] = merged[order]
    return out


def import_ulog(
    path: str | Path,
    vehicle: Vehicle | None = None,
    gyro_topic: str = "sensor_combined",
    motor_map: list[int] | None = None,
) -> tuple[FlightLog, dict]:
    try:
        from pyulog import ULog
    except ImportError:  # pragma: no cover - dependency of the package
        raise UserError("reading PX4 logs needs the Python package 'pyulog' (pip install pyulog)") from None
    path = Path(path)
    if gyro_topic not in GYRO_TOPICS:
        raise UserError(f"gyro topic {gyro_topic!r}: choose one of {', '.join(GYRO_TOPICS)}")
    if not path.is_file():
        raise UserError(f"cannot read {path}: no such file")
    chatter = io.StringIO()  # pyulog prints its corruption notes to stdout
    try:
        with contextlib.redirect_stdout(chatter):
            ulog = ULog(str(path), [gyro_topic, "sensor_combined", "esc_status"])
    except Exception as exc:  # pyulog raises assorted errors on foreign files
        raise UserError(f"{path}: not a readable PX4 ULog file ({exc})") from None
    if "corrupt" in chatter.getvalue():
        print(f"propid: warning: {path}: pyulog found corrupt records and skipped them", file=sys.stderr)
    try:
        return _from_ulog(ulog, path, vehicle, gyro_topic, motor_map)
    except (KeyError, IndexError, ValueError, TypeError) as exc:
        # A corrupt format definition leaves topics without the fields they should have.
        raise UserError(f"{path}: incomplete or corrupt PX4 ULog ({type(exc).__name__}: {exc})") from None


def _from_ulog(ulog, path: Path, vehicle: Vehicle | None, gyro_topic: str,
               motor_map: list[int] | None) -> tuple[FlightLog, dict]:
    def topic(name):
        found = [d for d in ulog.data_list if d.name == name]
        return min(found, key=lambda d: d.multi_id) if found else None

    gyro_data = topic(gyro_topic)
    if gyro_data is None or len(gyro_data.data["timestamp"]) == 0:
        raise UserError(f"{path}: topic {gyro_topic} not logged: no gyro samples (check SDLOG_PROFILE)")
    esc = topic("esc_status")
    if esc is None or len(esc.data["timestamp"]) == 0:
        raise UserError(
            f"{path}: topic esc_status not logged: no rotor speeds. Needs ESCs with RPM telemetry "
            "(DShot telemetry / bidirectional DShot, or UAVCAN ESCs) and esc_status in the log"
        )
    fmt = GYRO_TOPICS[gyro_topic]
    gyro_t = np.asarray(gyro_data.data["timestamp"], dtype=np.int64)
    gyro_cols = {
        f"gyro_{a}": np.asarray(gyro_data.data[fmt.format(i)], dtype=float) * FRD_TO_FLU[i]
        for i, a in enumerate("xyz")
    }
    if gyro_topic == "sensor_combined" and "accelerometer_m_s2[0]" in gyro_data.data:
        for i, a in enumerate("xyz"):
            gyro_cols[f"acc_{a}"] = np.asarray(gyro_data.data[f"accelerometer_m_s2[{i}]"], dtype=float) * FRD_TO_FLU[i]

    esc_t = np.asarray(esc.data["timestamp"], dtype=np.int64)
    slots = sorted(
        int(k.split("[")[1].split("]")[0]) for k in esc.data if k.startswith("esc[") and k.endswith("].esc_rpm")
    )
    counts = np.asarray(esc.data.get("esc_count", np.full(esc_t.size, len(slots))), dtype=int)
    motor_count = vehicle.rotor_count if vehicle is not None else (int(np.max(counts)) if counts.size else 0)
    if motor_count == 0 or motor_count > len(slots):
        raise UserError(f"{path}: esc_status reports {motor_count} ESCs, the log holds {len(slots)} rpm slots")
    if motor_map is None:
        motor_map, map_note = quadrant_map(vehicle, PX4_QUADX, motor_count)
    else:
        map_note = "given: vehicle rotor i <- motor " + ",".join(str(m + 1) for m in motor_map)
    rotor_cols = {}
    for rotor, motor in enumerate(motor_map, start=1):
        rpm = np.abs(np.asarray(esc.data[f"esc[{motor}].esc_rpm"], dtype=float))
        rotor_cols[f"omega_{rotor}"] = rpm * RPM_TO_RAD_S
    columns = merge_streams(gyro_t, gyro_cols, esc_t, rotor_cols)
    log = flightlog_from_columns(columns, str(path), None if vehicle is None else vehicle.rotor_count)
    info = {
        "format": "ulog",
        "gyro_topic": gyro_topic,
        "gyro_samples": int(gyro_t.size),
        "esc_samples": int(esc_t.size),
        "motor_map": [m + 1 for m in motor_map],
        "motor_map_note": map_note,
        "frame": "PX4 FRD -> FLU: (x, -y, -z)",
        "streams": "events",
    }
    return log, info
