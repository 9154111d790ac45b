"""What a replay is asked to do (ReplayOptions) and what it returns (ReplayResult)."""

from __future__ import annotations

from dataclasses import dataclass, field

US = 1_000_000  # microseconds per second: the C API takes time stamps in us


@dataclass
class ReplayOptions:
    segment: str = "all"  # "all" or "flying"
    start: str = "first"  # where the filter starts: "first" (the segment's first row) or "flying" (replay/start.py)
    streams: str = "auto"  # "auto", "rows" or "events"
    unit_inertia: bool = False
    kf_nominal: float | None = None  # override (unit-inertia mode: kf/J)
    km_nominal: float | None = None
    noise: str = "auto"  # "auto": from the log; "default": the library defaults
    max_rotor_speed: float | None = None  # None: realdata_checks.absurd_speed_limit (robust to spikes)
    overrides: dict = field(default_factory=dict)  # any other propid_config_t field
    skip_repeats: bool = False  # a row whose gyro (or rotor speeds) exactly repeat the previous row is no new sample
    # Telemetry delay, held by the filter itself (config.rotor_delay_us, docs/math.md §12):
    # esc_delay: seconds (> 0 the logged rotor speeds lag the gyro, < 0 the gyro lags), "auto" (the per-log
    # rule), "vehicle" (the vehicle file's esc_delay_s, 0 when absent), "default" (the file's when it has
    # one, else auto) or None: then the older rotor_delay_s applies, "push the rotor speeds this much
    # later" = esc_delay -rotor_delay_s ("auto" = the rule).
    esc_delay: float | str | None = None
    rotor_delay_s: float | str = 0.0
    prefilter_hz: float | str | None = None  # matched causal low-pass of gyro and rotor speed^2: Hz, "auto" or None
    diagnostic_highpass_hz: float | None = None  # diagnostic only: emulate removing slow content (docs/real-data.md)
    aiding: str = "auto"  # "gyro", "gyro+accel", or "auto": gyro+accel when the log has acc_* and the vehicle a mass
    disturbance: str = "off"  # "on": the filter's disturbance-torque states
    # Their bandwidth [Hz] (docs/math.md §7): the states take the torque residual below it (what the vehicle's
    # controller cancels) and the coefficients learn above it; None: the library's slow walk.
    disturbance_bandwidth: float | None = None
    rotor_inertia: str = "auto"  # "auto"/"on": the vehicle's rotor_inertia enters the model; "off"
    # The vehicle file's aero_damping (a body torque -d_a omega_a, docs/math.md §17): "auto"/"on" into the
    # filter's config when the file has it; "off".
    aero_damping: str = "off"
    # The vehicle file's gyro_scale undone at the boundary (gyro / scale): "auto" when the file has it; "off".
    # Off for library callers by default (a caller may have undone it on its log already); the CLI's default
    # is auto.
    gyro_scale: str = "off"
    # The vehicle file's airspeed terms of the rotor thrust (thrust_climb_coeff, thrust_translational_coeff;
    # replay/thrust_aero.py) removed from the accelerometer's z before it is pushed: "on" or "off".
    thrust_aero: str = "off"
    torque_scale: str = "auto"  # "auto"/"on": estimate the thrust-torque scale when the accelerometer is fused; "off"
    # Its random walk [1/sqrt(s)]: None (the library default, a constant), a number, or "auto" (replay/scale_walk.py).
    torque_scale_walk: float | str | None = None
    # "auto": the coefficients' relative walk (thrust_coeff_rel_walk) = sqrt(library walk^2 + q^2), q the same per-log
    # torque-gain rule (replay/scale_walk.py): without the scale state the kf states carry the changing gain.
    thrust_coeff_walk: str | None = None
    # Rotor-speed input error (docs/math.md §14): None (off), a std [rad/s], or "auto" (replay/input_noise.py);
    # its correlation time [s] (None: the rule's with auto, one step with a given std).
    rotor_speed_noise: float | str | None = None
    rotor_speed_noise_time: float | None = None
    # The rotor report's timing error (docs/math.md §14, "The report's timing"): None/"off", seconds, or "auto"
    # (replay/report_timing.py: the median interval between new rotor-speed samples). Off by default (the CLI's
    # too: it failed its default rule, docs/sitl.md "Log").
    rotor_timing_error: float | str | None = None
    # The errors-in-variables compensation of the coefficient update with that error (needs rotor_speed_noise).
    input_error_compensation: bool = False
    # The motor commands as the rotor input's instrument (docs/math.md §16): "off" or "commands" (the log's
    # cmd_i columns through propid_push_motor_command); the first stage's lag [s] or "auto" (the per-log rule,
    # replay/instrument.py) and its memory [s].
    instrument: str = "off"
    command_lag: float | str = "auto"
    command_memory: float | None = None
    # The first stage's weak-instrument guard: least F statistic of a rotor's fit (0: none).
    command_min_f: float = 0.0
    record_every: int = 1  # keep every k-th estimate for the time series
    # Every k-th recorded estimate, also the rotor mean kf's relative std from the filter's covariance (series
    # "kf_rotor_mean_rel_std", NaN between; gap's calibration guard reads it); 0: not recorded (it costs a copy
    # of the covariance per value).
    rotor_mean_std_every: int = 0
    # The window kf_mean_window/km_mean_window average over (replay/averaging.py): "from-crossing" or "at-least-half".
    mean_window: str = "from-crossing"
    # What kf_mean/km_mean report (replay/averaging.py): "inverse-variance" (the whole series weighted by
    # 1/std^2) or "window" (the window's plain mean); both are always in the summary.
    mean_estimator: str = "inverse-variance"
    progress: bool = True


@dataclass
class ReplayResult:
    summary: dict
    series: dict  # time series of the estimates (numpy arrays)

