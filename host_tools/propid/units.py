"""Unit and frame conversions at the boundary to other tools' conventions (one place each).

Inside propid everything is SI, body FLU, world ENU (z up), rotor speeds in rad/s.
MAVLink and PX4 use body FRD and world NED; ESC telemetry reports mechanical rpm.
"""

from __future__ import annotations

import math

import numpy as np

RPM_TO_RAD_S = 2.0 * math.pi / 60.0  # 1 rpm = 2 pi rad per 60 s

# Per-axis sign that turns a body FRD vector into body FLU (and back: it is its own inverse).
FRD_TO_FLU = np.array([1.0, -1.0, -1.0])


def rpm_to_rad_s(rpm: float) -> float:
    return float(rpm) * RPM_TO_RAD_S


def erpm_to_rad_s_factor(pole_pairs: float, erpm_scale: float = 1.0) -> float:
    """Factor from an electrical-rpm reading to mechanical rad/s: eRPM counts every
    electrical revolution, pole_pairs of them per mechanical one; erpm_scale is the unit
    the log stores (Betaflight logs eRPM/100, i.e. erpm_scale = 100)."""
    return erpm_scale / pole_pairs * RPM_TO_RAD_S


def frd_to_flu(vector) -> list[float]:
    """Body FRD -> body FLU (y and z change sign)."""
    return [float(vector[0]), -float(vector[1]), -float(vector[2])]


def ned_to_enu(vector) -> list[float]:
    """World NED -> world ENU."""
    return [float(vector[1]), float(vector[0]), -float(vector[2])]
