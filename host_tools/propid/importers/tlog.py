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

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle, flightlog_from_columns
from propid.importers.ulog import merge_streams
from propid.units import FRD_TO_FLU, RPM_TO_RAD_S


@dataclass
class TlogStreams:
    """What a tlog holds, each stream on the vehicle's own time stamps (time_usec), in
    the units found on the wire except the rotor speeds (already rad/s):
    - imu: rows (time_us, gx, gy, gz, ax, ay, az), body FRD, rad/s and m/s^2;
    - esc: {time_us: {esc_index: rotor speed [rad/s]}}: ESC_STATUS messages with the same
      time_usec are one rotor sample (a hexa/octo needs two messages); the sign of the
      rpm (spin direction on some ESCs) is dropped, rotor speeds are magnitudes;
    - estimates: rows of propid's own PROPID_* telemetry (columns of
      mavlink_io.estimate_columns), only when asked for."""

    imu: list[tuple] = field(default_factory=list)
    esc: dict[int, dict[int, float]] = field(default_factory=dict)
    estimates: list[dict] = field(default_factory=list)
    estimate_rotor_count: int | None = None

    def esc_count(self) -> int:
        """Highest ESC index that ever reported a non-zero speed, plus one (0 if none)."""
        used = [i for slots in self.esc.values() for i, speed in slots.items() if speed > 0]
        return max(used) + 1 if used else 0


def read_tlog_streams(path: str | Path, estimates: bool = False, progress: bool = False) -> TlogStreams:
    """Read a tlog once: HIGHRES_IMU, ESC_STATUS and (with estimates=True) PROPID_*.
    Our dialect is used to decode (pymavlink's bundled common.xml may lack ESC_STATUS;
    the propid dialect declares it with the standard id and wire format)."""
    from propid import mavlink_io

    streams = TlogStreams()
    types = {"HIGHRES_IMU", "ESC_STATUS"}
    assembler = None
    if estimates:
        assembler = mavlink_io.EstimateRows()
        types |= {mavlink_io.MSG_COEFFICIENTS, mavlink_io.MSG_GYRO, mavlink_io.MSG_STATUS, mavlink_io.MSG_MODEL}
    for msg in mavlink_io.read_tlog(path, types=types, progress=progress):
        kind = msg.get_type()
        if kind == "HIGHRES_IMU":
            streams.imu.append((int(msg.time_usec), msg.xgyro, msg.ygyro, msg.zgyro, msg.xacc, msg.yacc, msg.zacc))
        elif kind == "ESC_STATUS":
            slots = streams.esc.setdefault(int(msg.time_usec), {})
            for k, rpm in enumerate(msg.rpm):
                slots[int(msg.index) + k] = abs(float(rpm)) * RPM_TO_RAD_S
        elif assembler is not None:
            row = assembler.feed(msg)
            if row is not None:
                streams.estimates.append(row)
    if assembler is not None:
        streams.estimate_rotor_count = assembler.rotor_count
    return streams


def import_tlog(
    path: str | Path, vehicle: Vehicle | None = None, motor_map: list[int] | None = None
) -> tuple[FlightLog, dict]:
    path = Path(path)
    if not path.is_file():
        raise UserError(f"cannot read {path}: no such file")
    try:
        streams = read_tlog_streams(path)
    except UserError:
        raise
    except Exception as exc:  # pymavlink raises assorted errors on foreign files
        raise UserError(f"{path}: not a readable MAVLink tlog ({exc})") from None
    imu, esc = streams.imu, streams.esc
    if not imu:
        raise UserError(f"{path}: no HIGHRES_IMU messages: no gyro samples (stream HIGHRES_IMU from the vehicle)")
    if not esc:
        raise UserError(f"{path}: no ESC_STATUS messages: no rotor speeds (needs ESC RPM telemetry)")
    if vehicle is not None:
        count = vehicle.rotor_count
    else:
        count = streams.esc_count() or 4
    if motor_map is None:
        motor_map = list(range(count))
        map_note = "ESC i -> vehicle rotor i (identity)"
    else:
        map_note = "given: vehicle rotor i <- ESC " + ",".join(str(m + 1) for m in motor_map)
    imu_arr = np.array(sorted(imu, key=lambda r: r[0]), dtype=float)
    esc_times = np.array(sorted(esc), dtype=np.int64)
    rotor_cols = {
        f"omega_{rotor}": np.array([esc[t].get(motor, np.nan) for t in esc_times])
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
