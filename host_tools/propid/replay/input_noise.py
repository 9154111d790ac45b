"""The per-log rule for the rotor-speed input error (`--rotor-speed-noise auto`; the filter's
term: docs/math.md §14, config rotor_speed_noise / rotor_speed_noise_time).

Rule (developed on simulator flights with known coefficients, then run once unchanged on the
shared real logs; it reads only the rotor-speed stream, never the gyro, a coefficient or a
reference value):

- per rotor, over the flying rows, the NEW samples only: a row whose speed equals the
  previous row's is the same telemetry sample held (sample-and-hold repeats carry no error
  of their own);
- the error of one sample: the second difference of consecutive new samples,
  d_k = Omega_k - (Omega_(k-1) + Omega_(k+1)) / 2, has variance 1.5 sigma^2 for independent
  errors of std sigma, while the motion itself (a motor's speed is smooth at the telemetry
  rate) mostly cancels: sigma_w = 1.4826 MAD(d) / sqrt(1.5), robust to spikes; its
  correlation time: the median interval between new samples (one error stays in the
  input until the next sample replaces it);
- quantisation: the stream's step q near its median speed (the median gap between adjacent
  distinct values within +-QUANT_BAND of the median), std q / sqrt(12); its correlation time
  is how long a value stays on its step: with holds h_k between changes of the value and
  independent levels, the integral of the error's autocorrelation is sum(h^2) / sum(h)
  (a time-weighted mean hold: a speed that sits on one step keeps its error), bounded to
  [sample interval, MAX_TIME_S];
- the larger of the two parts with its correlation time (a grid crossed at every sample is
  already in the second difference; a slowly crossed one is not).
The filter gets the median over the rotors of both. Too few new samples (< MIN_SAMPLES on
every rotor): 0 (off).
"""

from __future__ import annotations

import numpy as np

from propid.flightlog import FlightLog
from propid.realdata_checks import absurd_speed_limit, clean_rotor_speeds
from propid.signals import repeats_previous_row

MIN_SAMPLES = 50
QUANT_BAND = 0.1  # +-10 % of the median speed: where the quantisation step is measured
MAX_TIME_S = 1.0  # this rule's ceiling and replay's bound (the firmware accepts up to 600 s)


def _resolution(values: np.ndarray) -> float:
    """The stream's quantisation step near its median speed: the median gap between adjacent
    distinct values within +-QUANT_BAND of the median (0 when the values are not on a grid)."""
    centre = float(np.median(values))
    near = np.unique(values[np.abs(values - centre) <= QUANT_BAND * centre])
    if len(near) < 3:
        return 0.0
    return float(np.median(np.diff(near)))


def estimate_rotor_speed_noise(log: FlightLog, mask: np.ndarray) -> dict:
    """rotor_speed_noise [rad/s] and rotor_speed_noise_time [s] by the rule above."""
    speeds, _ = clean_rotor_speeds(log.rotor_speed, absurd_speed_limit(log.rotor_speed))
    t = np.asarray(log.t, dtype=float)
    sigmas, times, parts = [], [], []
    for i in range(speeds.shape[1]):
        # The stream's own samples: the rows that log it (clean_rotor_speeds fills the others, e.g. an
        # events log's gyro rows, by interpolation: no samples), a value equal to the previous sample
        # being no new sample.
        column = np.where(np.isfinite(log.rotor_speed[:, i]), speeds[:, i], np.nan)
        keep = mask & np.isfinite(column) & ~repeats_previous_row(column[:, None])
        values, stamps = column[keep], t[keep]
        if len(values) < MIN_SAMPLES:
            continue
        interval = float(np.median(np.diff(stamps)))
        second = values[1:-1] - 0.5 * (values[:-2] + values[2:])
        mad = float(np.median(np.abs(second - np.median(second))))
        white_var = (1.4826 * mad) ** 2 / 1.5
        step = _resolution(values)
        quant_var = step * step / 12.0
        # The quantisation error stays while the value stays on its step: holds h between
        # changes, independent levels -> integral of the autocorrelation sum(h^2) / sum(h).
        holds = np.diff(stamps)
        quant_time = float(np.sum(holds ** 2) / np.sum(holds)) if np.sum(holds) > 0.0 else MAX_TIME_S
        quant_time = min(max(quant_time, interval), MAX_TIME_S)
        # A grid crossed at every sample already shows in the second difference: the larger
        # part, not the sum, with its own correlation time.
        if white_var <= 0.0 and quant_var <= 0.0:
            continue
        quantised = quant_var > white_var
        sigmas.append(float(np.sqrt(quant_var if quantised else white_var)))
        times.append(quant_time if quantised else interval)
        parts.append({"white": float(np.sqrt(white_var)), "interval": interval, "step": step,
                      "quant_time": quant_time})
    if not sigmas:
        return {"sigma": 0.0, "time": 0.0, "rotors": 0}
    return {"sigma": float(np.median(sigmas)), "time": min(max(float(np.median(times)), 0.0), MAX_TIME_S),
            "per_rotor": parts, "rotors": len(sigmas)}
