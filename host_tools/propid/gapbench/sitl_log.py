"""Fast reader of propid_sitl's own full logs (truth columns included) for the bench.

The bench reads several SITL logs per flight; the general flight-log v1 reader
validates every field and names bad ones, which is what a user's file needs but
slow here. These files come from our simulator: once the first gyro and rotor-speed
samples are in, every row is complete in the columns read below, so numpy's plain
loader does.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from propid.flightlog import FlightLog

_WANTED = re.compile(r"^(t|gyro_[xyz]|acc_[xyz]|q[wxyz]|v[xyz]|p[xyz]|omega_\d+|true_k[fm]_\d+)$")


def read_sitl_log(path: Path) -> FlightLog:
    path = Path(path)
    with path.open(encoding="utf-8") as f:
        header = f.readline().strip().split(",")
        use = [i for i, name in enumerate(header) if _WANTED.match(name)]
        # Skip the first rows, logged before the first gyro or rotor-speed sample.
        skip = 1
        for line in f:
            fields = line.rstrip("\n").split(",")
            if all(fields[i] not in ("", "nan") for i in use):
                break
            skip += 1
    names = [header[i] for i in use]
    data = np.loadtxt(path, delimiter=",", skiprows=skip, usecols=use, ndmin=2)
    cols = {name: data[:, k] for k, name in enumerate(names)}
    count = sum(1 for n in names if n.startswith("omega_"))
    return FlightLog(
        t=cols.pop("t"),
        gyro=np.column_stack([cols.pop(f"gyro_{a}") for a in "xyz"]),
        rotor_speed=np.column_stack([cols.pop(f"omega_{i}") for i in range(1, count + 1)]),
        extra=cols,
        path=path,
    )
