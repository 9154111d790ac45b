"""The vehicle file's model keys the replay carries into the filter (docs/flightlog.md):
`gyro_scale` (the gyro reads s_a x the true rate: undone at the boundary, where the log's
units are converted, so every later step sees the true rate) and `aero_damping` (a body
torque -d_a omega_a: the firmware's config.aero_damping, docs/math.md §17). Each says
in the replay JSON's config_notes where its value came from."""

from __future__ import annotations

import copy

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.replay.options import ReplayOptions


def undo_gyro_scale(log: FlightLog, vehicle: Vehicle, options: ReplayOptions) -> tuple[FlightLog, str]:
    """The log with its gyro divided by the file's gyro_scale (`--gyro-scale auto`), and the note."""
    if options.gyro_scale not in ("auto", "off"):
        raise UserError(f"--gyro-scale {options.gyro_scale!r}: choose auto or off")
    scale = vehicle.gyro_scale
    if scale is None:
        return log, "none (the vehicle file has no gyro_scale)"
    if options.gyro_scale == "off":
        return log, f"not undone (--gyro-scale off; the vehicle file has {list(scale)})"
    out = copy.copy(log)
    out.gyro = log.gyro / np.asarray(scale, dtype=float)[None, :]
    return out, f"vehicle file: the gyro divided by {[float(v) for v in scale]} per axis before the filter"


def resolve_aero_damping(vehicle: Vehicle, options: ReplayOptions, config: dict, notes: dict) -> None:
    """config['aero_damping'] from the file's aero_damping (auto/on), or none."""
    if options.aero_damping not in ("auto", "on", "off"):
        raise UserError(f"--aero-damping {options.aero_damping!r}: choose auto, on or off")
    damping = vehicle.aero_damping
    if options.aero_damping == "on" and damping is None:
        raise UserError("--aero-damping on needs 'aero_damping' in the vehicle file")
    if damping is None or options.aero_damping == "off":
        notes["aero_damping"] = "not modelled" + (f" (--aero-damping off; the vehicle file has {list(damping)})"
                                                  if damping is not None else "")
        return
    if options.unit_inertia:
        notes["aero_damping"] = "not modelled (unit-inertia mode: the file's N m s/rad need the inertia)"
        return
    values = [float(v) for v in damping]
    if any(v < 0.0 for v in values):
        raise UserError(f"vehicle file {vehicle.path or vehicle.name}: aero_damping {values} has a negative "
                        "component; the filter models damping (>= 0 N m s/rad) only: give --aero-damping off")
    config["aero_damping"] = values
    notes["aero_damping"] = f"vehicle file: {values} N m s/rad (body torque -d_a omega_a)"
