"""Replay a flight log through the firmware filter itself (C library via ctypes).

One module per concern: options (what is asked), run (the sample loop), session (the C
filter behind it), config (the filter configuration and where each value came from),
noise (noise levels: measured on the log, or tuned on the innovations), alignment
(streams and rotor delay), calibration (the gyro-only torque-gain calibration with
the accelerometer, --vehicle-out), scale_walk (the per-log torque-gain walk rule), prefilter (matched low-pass, diagnostic high-pass) and fleet
(several runs of one vehicle). Plots live in propid.plotting, shared signal processing
in propid.signals.

Both streams are pushed as recorded, at the log's own times:
- "rows" logs (one row = one gyro sample and one rotor sample, e.g. the SITL, the
  Crazyflie and Betaflight CSVs): every row pushes its rotor speeds, then its gyro. A
  row with a missing (NaN) or absurd rotor speed is pushed anyway and the filter
  rejects it (counted by reason); the filter keeps the previous rotor speeds.
- "events" logs (each stream on its own time base, as the ULog and tlog importers write
  them: gyro rows have empty omega_*, rotor rows have empty gyro_*): a row pushes only
  the stream it carries.
A gyro push answered with PROPID_ERR_TIME_JUMP (a gap, e.g. a cut-out segment) is
followed by propid_resync() at that time and pushed again.

Definitions used in the output (docs/real-data.md):
- converged part of a coefficient: from the first replayed gyro sample at which its
  relative std falls below config.converged_rel_std to the end (the filter's own
  "converged" flag asks 3 std below it and the consistency monitor's vouching);
  kf_mean/km_mean average the estimate over it. A coefficient that never converges is
  averaged over the second half of the replayed samples and flagged converged = false.
  With mean_window "at-least-half" the window starts at the midpoint when that is earlier
  (replay/averaging.py); kf_mean_from_s/km_mean_from_s say where each window starts.
  That window's mean is kf_mean_window (km_mean_window); kf_mean_inverse_variance is every
  recorded estimate weighted by 1/std^2; kf_mean_smoothed the time mean of the estimate
  smoothed backwards under the coefficient walk; mean_estimator says which kf_mean is.
- unit-inertia mode (vehicle without inertia, e.g. the Betaflight file): the filter
  runs with J = identity [kg m^2], so its "kf" is kf/J (roll/pitch; one J for both)
  and its "km" is km/Jzz, in the vehicle file's (possibly assumed) geometry. Ratios
  between rotors and changes over time are meaningful; absolute kf and km are not.
"""

from propid.replay.alignment import (
    DELAY_BAND_HZ,
    MAX_ROTOR_DELAY_S,
    detect_streams,
    estimate_rotor_delay,
    filter_input_rule,
    probe_input_ratio,
)
from propid.replay.config import build_config
from propid.replay.fleet import fleet_summary, validation_table
from propid.replay.noise import NIS_MAX_ITERATIONS, NIS_TOLERANCE, estimate_noise, nis_mean, replay_nis
from propid.replay.options import US, ReplayOptions, ReplayResult
from propid.replay.prefilter import (
    CASCADE_3DB,
    COHERENCE_SMOOTH_HZ,
    COHERENCE_THRESHOLD,
    COHERENCE_WINDOW_S,
    coherence_cutoff,
    highpass_emulation_log,
    lowpass_pole,
    matched_lowpass,
    noise_gain,
    prefilter_log,
    torque_coherence,
)
from propid.replay.run import replay
from propid.replay.session import FilterSession, segment_mask

__all__ = [
    "CASCADE_3DB", "COHERENCE_SMOOTH_HZ", "COHERENCE_THRESHOLD", "COHERENCE_WINDOW_S", "DELAY_BAND_HZ",
    "MAX_ROTOR_DELAY_S", "NIS_MAX_ITERATIONS", "NIS_TOLERANCE", "US", "FilterSession", "ReplayOptions",
    "ReplayResult", "build_config", "coherence_cutoff", "detect_streams", "estimate_noise", "estimate_rotor_delay",
    "filter_input_rule", "probe_input_ratio", "fleet_summary", "highpass_emulation_log", "lowpass_pole", "matched_lowpass",
    "nis_mean", "noise_gain", "prefilter_log", "replay", "replay_nis", "segment_mask", "torque_coherence",
    "validation_table",
]
