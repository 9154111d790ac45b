"""propid_sitl's own full log (truth columns included) as a FlightLog, for the bench.

Read with the format's table reader (propid.flightlog.read_table: these files carry
more than a flight log); rows logged before the first gyro and rotor-speed samples
are dropped, the truth columns (true_kf_i, true_km_i) stay in `extra`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from propid.flightlog import FlightLog, read_table


def read_sitl_log(path: Path) -> FlightLog:
    columns = read_table(Path(path))
    count = sum(1 for name in columns if name.startswith("omega_"))
    gyro = np.column_stack([columns[f"gyro_{a}"] for a in "xyz"])
    speed = np.column_stack([columns[f"omega_{i}"] for i in range(1, count + 1)])
    complete = np.all(np.isfinite(gyro), axis=1) & np.all(np.isfinite(speed), axis=1)
    first = int(np.argmax(complete))
    extra = {name: values[first:] for name, values in columns.items()
             if name in ("acc_x", "acc_y", "acc_z", "qw", "qx", "qy", "qz", "vx", "vy", "vz",
                         "px", "py", "pz") or name.startswith(("true_kf_", "true_km_"))}
    return FlightLog(t=columns["t"][first:], gyro=gyro[first:], rotor_speed=speed[first:],
                     extra=extra, path=Path(path))
