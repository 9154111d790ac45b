"""MAVLink telemetry log (.tlog, as `propid log` or QGroundControl/MAVProxy write it)
-> flight-log v1.

Standard messages only, so a tlog from any autopilot that sends them works:
- HIGHRES_IMU: time_usec, xgyro/ygyro/zgyro [rad/s], xacc/yacc/zacc [m/s^2], FRD;
- ESC_STATUS: index (first ESC of the message), time_usec, rpm[4] [rpm].

MAVLink bodies are FRD: v_FLU = (x, -y, -z). ESC_STATUS slot k of message `index` is
ESC index+k; by default ESC i is the vehicle file's rotor i (propid's own SITL sends
them in vehicle order); --motor-map reorders. ESC_STATUS messages with the same
time_usec are one rotor sample (a hexa/octo needs two messages).

Timing uses the vehicle's time_usec (not the tlog's receive time), so both streams keep
their own time base: the output is event-style like the ULog importer's.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle, flightlog_from_columns
from propid.importers.ulog import FRD_TO_FLU, merge_streams

RPM_TO_RAD_S = 2.0 * math.pi / 60.0


def _messages(path: Path):
    """HIGHRES_IMU and ESC_STATUS messages of the tlog, read with engineer M's
    propid.mavlink_io (our dialect: pymavlink 2.4.50's common.xml lacks ESC_STATUS, the
    propid dialect declares it with the standard id and wire format)."""
    from propid.mavlink_io import read_tlog

    yield from read_tlog(path, types=["HIGHRES_IMU", "ESC_STATUS"])


def read_tlog_streams(path: Path) -> tuple[list[tuple], dict[int, dict[int, float]]]:
    """(imu rows [(time_us, gx, gy, gz, ax, ay, az)], esc {time_us: {esc_index: rpm}})."""
    imu = []
    esc: dict[int, dict[int, float]] = {}
    for msg in _messages(path):
        kind = msg.get_type()
        if kind == "HIGHRES_IMU":
            imu.append((int(msg.time_usec), msg.xgyro, msg.ygyro, msg.zgyro, msg.xacc, msg.yacc, msg.zacc))
        elif kind == "ESC_STATUS":
            slots = esc.setdefault(int(msg.time_usec), {})
            for k, rpm in enumerate(msg.rpm):
                slots[int(msg.index) + k] = abs(float(rpm))
    return imu, esc


def import_tlog(
    path: str | Path, vehicle: Vehicle | None = None, motor_map: list[int] | None = None
) -> tuple[FlightLog, dict]:
    path = Path(path)
    if not path.is_file():
        raise UserError(f"cannot read {path}: no such file")
    try:
        imu, esc = read_tlog_streams(path)
    except UserError:
        raise
    except Exception as exc:  # pymavlink raises assorted errors on foreign files
        raise UserError(f"{path}: not a readable MAVLink tlog ({exc})") from None
    if not imu:
        raise UserError(f"{path}: no HIGHRES_IMU messages: no gyro samples (stream HIGHRES_IMU from the vehicle)")
    if not esc:
        raise UserError(f"{path}: no ESC_STATUS messages: no rotor speeds (needs ESC RPM telemetry)")
    if vehicle is not None:
        count = vehicle.rotor_count
    else:  # highest ESC index that ever reported a non-zero speed
        used = [i for slots in esc.values() for i, rpm in slots.items() if rpm > 0]
        count = max(used) + 1 if used else 4
    if motor_map is None:
        motor_map = list(range(count))
        map_note = "ESC i -> vehicle rotor i (identity)"
    else:
        map_note = "given: vehicle rotor i <- ESC " + ",".join(str(m + 1) for m in motor_map)
    imu_arr = np.array(sorted(imu, key=lambda r: r[0]), dtype=float)
    esc_times = np.array(sorted(esc), dtype=np.int64)
    rotor_cols = {
        f"omega_{rotor}": np.array([esc[t].get(motor, np.nan) for t in esc_times]) * RPM_TO_RAD_S
        for rotor, motor in enumerate(motor_map, start=1)
    }
    gyro_cols = {f"gyro_{a}": imu_arr[:, 1 + i] * FRD_TO_FLU[i] for i, a in enumerate("xyz")}
    gyro_cols.update({f"acc_{a}": imu_arr[:, 4 + i] * FRD_TO_FLU[i] for i, a in enumerate("xyz")})
    columns = merge_streams(imu_arr[:, 0].astype(np.int64), gyro_cols, esc_times, rotor_cols)
    log = flightlog_from_columns(columns, str(path), None if vehicle is None else vehicle.rotor_count)
    info = {
        "format": "tlog",
        "gyro_samples": int(imu_arr.shape[0]),
        "esc_samples": int(esc_times.size),
        "motor_map": [m + 1 for m in motor_map],
        "motor_map_note": map_note,
        "frame": "MAVLink FRD -> FLU: (x, -y, -z)",
        "streams": "events",
    }
    return log, info
