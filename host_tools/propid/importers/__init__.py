"""Importers: one module per foreign log format, each returning (FlightLog, info).

`import_log(path, fmt)` dispatches; `detect_format(path)` guesses from the file's
first bytes and its extension.
"""

from __future__ import annotations

from pathlib import Path

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle

FORMATS = ("auto", "betaflight", "ulog", "tlog", "csv")

_BLACKBOX_MAGIC = b"H Product:Blackbox"
_ULOG_MAGIC = b"ULog\x01\x12\x35"


def detect_format(path: str | Path) -> str:
    path = Path(path)
    try:
        with open(path, "rb") as handle:
            head = handle.read(64)
    except OSError as exc:
        raise UserError(f"cannot read {path}: {exc.strerror or exc}") from None
    if head.startswith(_BLACKBOX_MAGIC):
        return "betaflight"
    if head.startswith(_ULOG_MAGIC):
        return "ulog"
    suffix = path.suffix.lower()
    if suffix == ".tlog":
        return "tlog"
    if suffix == ".csv":
        return "csv"
    # a tlog record is an 8-byte timestamp then a MAVLink start byte (0xFE v1, 0xFD v2)
    if len(head) > 8 and head[8] in (0xFE, 0xFD):
        return "tlog"
    raise UserError(
        f"{path}: cannot tell the log format (not a Betaflight blackbox, PX4 ULog, MAVLink tlog or .csv); "
        "give --format"
    )


def import_log(
    path: str | Path,
    fmt: str = "auto",
    vehicle: Vehicle | None = None,
    log_index: int | None = None,
    motor_map: list[int] | None = None,
    gyro_topic: str = "sensor_combined",
    progress: bool = False,
) -> tuple[FlightLog, dict]:
    """Read any supported log into flight-log v1 units and frames."""
    if fmt not in FORMATS:
        raise UserError(f"unknown format {fmt!r}: choose one of {', '.join(FORMATS)}")
    if fmt == "auto":
        fmt = detect_format(path)
    if fmt == "betaflight":
        from propid.importers.betaflight import import_betaflight

        return import_betaflight(path, vehicle, log_index, motor_map, progress)
    if fmt == "ulog":
        from propid.importers.ulog import import_ulog

        return import_ulog(path, vehicle, gyro_topic, motor_map)
    if fmt == "tlog":
        from propid.importers.tlog import import_tlog

        return import_tlog(path, vehicle, motor_map)
    from propid.importers.csv_v1 import import_csv

    return import_csv(path, vehicle)
