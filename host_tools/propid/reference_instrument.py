"""Mirror of propid_instrument.c (docs/math.md §16) in float64: the motor commands' first
stage, per rotor a first-order lag of the command and the fit y = u / max_rotor_speed^2 =
a + b z + c z^2 (z = lagged command - 1/2), b and c from the increments between rotor
samples, a from the levels' weighted means, with exponential forgetting; with min_f > 0 a
rotor keeps its telemetry while its fit's F statistic over the effective count (sum w)^2 /
sum w^2 is below min_f (the weak-instrument guard)."""

from __future__ import annotations

import math

import numpy as np

MIN_SAMPLES = 50  # C: PROPID_INSTRUMENT_MIN_SAMPLES
RIDGE = 1.0e-6  # C: PROPID_INSTRUMENT_RIDGE


class FirstStage:
    def __init__(self, rotor_count: int, lag_s: float, memory_s: float, max_rotor_speed: float,
                 rotor_stale_us: int, max_gyro_gap_us: int, min_f: float = 0.0):
        self.rotor_count = rotor_count
        self.lag_s = lag_s
        self.memory_s = memory_s
        self.full_sq = max_rotor_speed * max_rotor_speed
        self.rotor_stale_us = rotor_stale_us
        self.max_gyro_gap_us = max_gyro_gap_us
        self.min_f = min_f
        self.clear()

    def clear(self) -> None:
        n = self.rotor_count
        self.command = np.zeros(n)
        self.lagged = np.zeros(n)
        self.moment = np.zeros((n, 10))
        self.weight_sq = 0.0
        self.previous = np.zeros((n, 3))
        self.command_time_us = 0
        self.fit_time_us = 0
        self.fit_samples = 0
        self.has_command = False

    def push(self, t_us: int, command: np.ndarray) -> None:
        """An accepted command (the caller validated it)."""
        gap = int(t_us) - self.command_time_us
        continues = self.has_command and gap <= self.max_gyro_gap_us
        decay = math.exp(-gap * 1.0e-6 / self.lag_s) if continues else 0.0
        held = self.command if continues else command
        self.lagged = held + (self.lagged - held) * decay
        self.command = np.array(command, dtype=float)
        self.command_time_us = int(t_us)
        self.has_command = True

    def _value(self, m: np.ndarray, z: float) -> float | str | None:
        """The fit's value, None when singular, "weak" when it fails the guard."""
        ridge = RIDGE * (m[4] + m[6])
        s11, s12, s22 = m[4] + ridge, m[5], m[6] + ridge
        det = s11 * s22 - s12 * s12
        if not (m[0] > 0.0 and s11 > 0.0 and det > 1.0e-6 * s11 * s22):
            return None
        b = (s22 * m[7] - s12 * m[8]) / det
        c = (s11 * m[8] - s12 * m[7]) / det
        a = (m[3] - b * m[1] - c * m[2]) / m[0]
        value = a + z * (b + z * c)
        if not math.isfinite(value):
            return None
        if self.min_f > 0.0:
            cross = s11 * m[8] - s12 * m[7]  # C's form: dz's part + dz2's part orthogonal to dz
            explained = m[7] * m[7] / s11 + cross * cross / det / s11
            residual = m[9] - explained
            n_eff = m[0] * m[0] / self.weight_sq if self.weight_sq > 0.0 else 0.0
            if not explained * (n_eff - 2.0) >= 2.0 * self.min_f * residual:
                return "weak"
        return value

    def input(self, t_us: int, speed_sq: list[float]) -> tuple[list[float], bool, int]:
        """The rotor input of an accepted rotor sample, whether every rotor's came from the fit, and
        how many rotors the guard left to the telemetry."""
        out = list(speed_sq)
        t_us = int(t_us)
        if not self.has_command or t_us > self.command_time_us + self.rotor_stale_us:
            return out, False, 0
        decay = math.exp(-(t_us - self.command_time_us) * 1.0e-6 / self.lag_s) if t_us > self.command_time_us else 1.0
        if self.fit_samples > 0 and t_us > self.fit_time_us:
            forget = math.exp(-(t_us - self.fit_time_us) * 1.0e-6 / self.memory_s)
        else:
            forget = 1.0 if self.fit_samples > 0 else 0.0
        valid = self.fit_samples >= MIN_SAMPLES
        projected = 0
        guarded = 0
        for i in range(self.rotor_count):
            m = self.moment[i]
            held = self.command[i]
            z = held + (self.lagged[i] - held) * decay - 0.5
            y = speed_sq[i] / self.full_sq
            value = self._value(m, z) if valid else None
            if value == "weak":
                guarded += 1
            elif value is not None:
                out[i] = min(max(value, 0.0), 1.0) * self.full_sq
                projected += 1
            z2 = z * z
            dz, dz2, dy = z - self.previous[i, 0], z2 - self.previous[i, 1], y - self.previous[i, 2]
            inc = 1.0 if self.fit_samples > 0 else 0.0
            term = np.array([1.0, z, z2, y, inc * dz * dz, inc * dz * dz2, inc * dz2 * dz2, inc * dz * dy,
                             inc * dz2 * dy, inc * dy * dy])
            self.moment[i] = forget * m + term
            self.previous[i] = (z, z2, y)
        self.weight_sq = forget * forget * self.weight_sq + 1.0
        self.fit_time_us = t_us
        self.fit_samples += 1
        return out, projected == self.rotor_count, guarded
