"""Flight-log v1 CSV -> flight-log v1: validate against the spec and the vehicle file,
and normalise (missing values written as empty fields, numbers in one format)."""

from __future__ import annotations

from pathlib import Path

from propid.flightlog import FlightLog, Vehicle, read_flightlog


def import_csv(path: str | Path, vehicle: Vehicle | None = None) -> tuple[FlightLog, dict]:
    log = read_flightlog(path, vehicle)
    return log, {"format": "csv", "frame": "already FLU / SI (flight-log v1)"}
