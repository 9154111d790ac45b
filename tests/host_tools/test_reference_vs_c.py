"""The C filter (through ctypes) against the float64 numpy reference of the same
algorithm, on a recorded synthetic flight. Tolerance and its derivation:
docs/design.md, "C filter vs float64 reference".

The sequence: an X quad (Hummingbird-class) with per-rotor coefficients off the
nominal, an excitation torque plus a rate-hold loop, ESC speeds at 250 Hz and
gyro at 500 Hz (white noise + bias), 5 s, a few gross gyro outliers (gated by
both filters) and one propid_reset_rotor. Both filters get identical inputs.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from propid.cfilter import (MODEL_TERMS, STATUS, CFilter, FilterConfig, c_default_tuning, DEFAULT_TUNING, library_path,
                            load_library)
from propid.errors import UserError
from propid.reference_filter import ReferenceFilter

# Agreement bounds (derived in docs/design.md):
STATE_TOL_SIGMA = 0.02   # |x_C - x_ref| <= 0.02 * std_ref for every state, every sample
COV_TOL_REL = 2.0e-3     # |P_ii,C - P_ii,ref| <= 2e-3 * P_ii,ref for every variance, every sample



@pytest.fixture(scope="module", autouse=True)
def library():
    """The C library must be built (cmake target propid_shared): a missing library
    is a failure with the path in the message, not a skip."""
    try:
        return load_library()
    except UserError as exc:
        pytest.fail(str(exc))


MASS = 1.8  # the flight's collective thrust is ~18 N


def make_config(options: str = "plain") -> FilterConfig:
    """plain: the 14-state filter; all: disturbance torque, rotor inertia and the
    accelerometer with the thrust-torque scale (19 states, the generic step and the scalar update
    everywhere)."""
    inertia = [3.65e-3, 3.68e-3, 7.03e-3]
    config = FilterConfig.symmetric(4, 0.17, math.pi / 4, 1.0, 5.57e-6, 1.36e-7, inertia)
    if options == "all":
        config = config.with_overrides(disturbance_torque=1, rotor_inertia=[2e-6] * 4, mass=MASS,
                                       accel_noise_std=0.3, torque_scale=1,
                                       torque_scale_walk=0.05)
    return config


def record_flight(seed: int = 7, duration_s: float = 5.0):
    """Events (t_us, kind, values) of a simulated flight, in push order."""
    rng = np.random.default_rng(seed)
    config = make_config()
    inertia = np.diag(np.array(config.inertia).diagonal())
    j_diag = np.diag(inertia)
    positions = np.array(config.positions)
    yaw = np.array(config.yaw_signs)
    kf_true = 5.57e-6 * (1.0 + rng.uniform(-0.2, 0.2, 4))
    km_true = 1.36e-7 * (1.0 + rng.uniform(-0.2, 0.2, 4))
    bias = rng.uniform(-0.03, 0.03, 3)
    gyro_std = config.gyro_noise_density * math.sqrt(500.0)
    # Nominal allocation matrix: torque = T u.
    t_matrix = np.vstack([positions[:, 1] * 5.57e-6, -positions[:, 0] * 5.57e-6, yaw * 1.36e-7])
    t_pinv = np.linalg.pinv(t_matrix)
    hover_sq = (0.6 * 1500.0) ** 2

    rate = np.zeros(3)
    speeds = np.zeros(4)
    events = []
    physics_us, gyro_us, esc_us = 250, 2000, 4000
    end_us = int(duration_s * 1e6)
    outliers = {int(1.2e6), int(2.5e6), int(3.7e6)}
    for t_us in range(0, end_us + 1, physics_us):
        t = t_us * 1e-6
        if t_us % gyro_us == 0 and t_us > 0:
            gyro = rate + bias + gyro_std * rng.standard_normal(3)
            if t_us in outliers:
                gyro[t_us % 3] += 5.0
            events.append((t_us, "gyro", gyro.tolist()))
        if t_us == int(3.0e6):
            events.append((t_us, "reset_rotor", 2))
        if t_us % esc_us == 0:
            accel = 20.0 * np.array([math.sin(2 * math.pi * 1.3 * t), math.sin(2 * math.pi * 1.7 * t + 1.0),
                                     0.8 * math.sin(2 * math.pi * 0.9 * t + 2.0)])
            torque = j_diag * (accel - 4.0 * rate)
            collective = hover_sq * (1.0 + 0.25 * math.sin(2 * math.pi * 0.6 * t))
            u = collective + t_pinv @ (torque - t_matrix @ np.full(4, collective))
            speeds = np.sqrt(np.clip(u, 0.0, None))
            speeds *= 1.0 + 0.03 * np.sin(2 * math.pi * (2.3 + 0.7 * np.arange(4)) * t + np.arange(4))
            speeds = np.minimum(speeds, 1500.0)
            events.append((t_us, "rotor", speeds.tolist()))
            force_z = float(np.sum(kf_true * speeds ** 2)) / MASS + 0.1 + 0.3 * rng.standard_normal()
            if t_us == int(2.0e6):
                force_z += 50.0  # one gross accelerometer outlier
            events.append((t_us, "accel", [0.0, 0.0, force_z]))
        u_sq = speeds ** 2
        thrust = kf_true * u_sq
        tau = np.array([np.sum(positions[:, 1] * thrust), -np.sum(positions[:, 0] * thrust),
                        np.sum(yaw * km_true * u_sq)])

        def rate_dot(w):
            return (tau - np.cross(w, j_diag * w)) / j_diag

        h = physics_us * 1e-6
        rate = rate + h * rate_dot(rate + 0.5 * h * rate_dot(rate))
    return events


def replay(filt, events, perturb_at=None):
    """Run the events through one filter; per gyro sample, (status, state, cov)."""
    trace = []
    for t_us, kind, values in events:
        if kind == "rotor":
            assert filt.push_rotor_speeds(t_us, values) in (STATUS["PROPID_OK"], STATUS["PROPID_OK_QUEUED"])
        elif kind == "accel":
            if filt.config.mass > 0.0:
                status = filt.push_accel(t_us, values)
                state, cov = filt.scaled_state()
                trace.append((status, state, np.diag(cov).copy()))
        elif kind == "command":
            if filt.config.motor_command_instrument:
                assert filt.push_motor_command(t_us, values) == STATUS["PROPID_OK"]
        elif kind == "reset_rotor":
            assert filt.reset_rotor(values) == STATUS["PROPID_OK"]
        else:
            gyro = list(values)
            if perturb_at is not None and t_us == perturb_at:
                gyro[0] += 0.01
            status = filt.push_gyro(t_us, gyro)
            state, cov = filt.scaled_state()
            trace.append((status, state, np.diag(cov).copy()))
    return trace


def disagreement(trace_c, trace_ref):
    """max |dx| / std_ref and max relative variance difference, over samples and states."""
    worst_state, worst_cov = 0.0, 0.0
    for (status_c, x_c, var_c), (status_r, x_r, var_r) in zip(trace_c, trace_ref):
        if status_c != status_r:
            return math.inf, math.inf
        worst_state = max(worst_state, float(np.max(np.abs(x_c - x_r) / np.sqrt(var_r))))
        worst_cov = max(worst_cov, float(np.max(np.abs(var_c - var_r) / var_r)))
    return worst_state, worst_cov


@pytest.fixture(scope="module")
def flight():
    return record_flight()


@pytest.fixture(scope="module")
def reference_trace(flight):
    return replay(ReferenceFilter(make_config()), flight)


def test_c_agrees_with_reference_with_every_option(flight):
    """Disturbance torque, rotor inertia and accelerometer aiding on: same bounds."""
    config = make_config("all")
    trace_ref = replay(ReferenceFilter(config), flight)
    trace_c = replay(CFilter(config), flight)
    assert len(trace_c) == len(trace_ref) > 3000
    assert len(trace_c[0][1]) == 19
    statuses = [s for s, _, _ in trace_c]
    print("gated samples:", statuses.count(STATUS["PROPID_OK_GATED"]))
    assert statuses.count(STATUS["PROPID_OK_GATED"]) >= 4  # three gyro outliers, one accelerometer
    state_err, cov_err = disagreement(trace_c, trace_ref)  # inf when any status differs
    print(f"C vs reference, every option: max |dx|/std = {state_err:.3g}, max |dP_ii|/P_ii = {cov_err:.3g}")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL


def test_c_agrees_with_reference_with_a_disturbance_bandwidth(flight):
    """Every option with the disturbance states given a 5 Hz bandwidth (their walk 2 pi f x the rate process
    noise, docs/math.md §7): same bounds, and the states then move with the residual torque (their walk is
    31 rad/s^2/sqrt(s) here against 0.2 by default)."""
    slow = make_config("all")
    config = slow.with_overrides(disturbance_bandwidth=5.0, rate_process_noise=1.0)
    trace_ref = replay(ReferenceFilter(config), flight)
    trace_c = replay(CFilter(config), flight)
    assert len(trace_c) == len(trace_ref) > 3000
    state_err, cov_err = disagreement(trace_c, trace_ref)
    print(f"C vs reference, disturbance bandwidth: max |dx|/std = {state_err:.3g}, max |dP_ii|/P_ii = {cov_err:.3g}")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL
    # The bandwidth changed the filter: the disturbance variances at the end are far above the slow walk's.
    slow_c = replay(CFilter(slow.with_overrides(rate_process_noise=1.0)), flight)
    disturbance = slice(14, 17)
    assert np.all(trace_c[-1][2][disturbance] > 10.0 * slow_c[-1][2][disturbance])


AERO_DAMPING = [0.01, 0.012, 0.02]  # [N m s/rad]: decay rates 2.7 / 3.3 / 2.8 1/s on this inertia


@pytest.mark.parametrize("options", ["plain", "all"])
def test_c_agrees_with_reference_with_aero_damping(flight, options):
    """A known aerodynamic rate damping (docs/math.md §17): same bounds, and the term changes the run (the
    comparison would see it missing on one side)."""
    config = make_config(options).with_overrides(aero_damping=AERO_DAMPING)
    trace_ref = replay(ReferenceFilter(config), flight)
    trace_c = replay(CFilter(config), flight)
    assert len(trace_c) == len(trace_ref) > 2000
    state_err, cov_err = disagreement(trace_c, trace_ref)
    print(f"C vs reference, aero damping ({options}): max |dx|/std = {state_err:.3g}, "
          f"max |dP_ii|/P_ii = {cov_err:.3g}")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL
    without = replay(CFilter(make_config(options)), flight)
    moved, _ = disagreement(trace_c, without)
    assert moved > 1.0  # the term moves the estimate by more than its std somewhere
    assert CFilter(config).estimate().model_terms & MODEL_TERMS["AERO_DAMPING"]


@pytest.mark.parametrize("options", ["plain", "all"])
def test_c_agrees_with_reference_with_input_noise(flight, options):
    """Rotor-speed input error in the rate process noise (docs/math.md §14): same bounds, and the
    term changes the run (the comparison would see it missing on one side)."""
    config = make_config(options).with_overrides(rotor_speed_noise=20.0, rotor_speed_noise_time=0.01)
    trace_ref = replay(ReferenceFilter(config), flight)
    trace_c = replay(CFilter(config), flight)
    state_err, cov_err = disagreement(trace_c, trace_ref)
    print(f"C vs reference, input noise ({options}): max |dx|/std = {state_err:.3g}, "
          f"max |dP_ii|/P_ii = {cov_err:.3g}")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL
    _, cov_off = disagreement(replay(CFilter(make_config(options)), flight), trace_ref)
    assert cov_off > 10.0 * COV_TOL_REL


@pytest.mark.parametrize("options", ["plain", "all"])
@pytest.mark.parametrize("speed_noise", [0.0, 20.0])
def test_c_agrees_with_reference_with_the_report_timing(flight, options, speed_noise):
    """The rotor report's timing error (rotor_timing_error, docs/math.md §14 "The report's timing"): a rank-one
    rate block from the speeds' change over the step, alone and beside the speed error; same bounds, and the term
    changes the run (the comparison would see it missing on one side)."""
    without = make_config(options).with_overrides(rotor_speed_noise=speed_noise,
                                                  rotor_speed_noise_time=0.01 if speed_noise else 0.0)
    config = without.with_overrides(rotor_timing_error=0.001)
    trace_ref = replay(ReferenceFilter(config), flight)
    trace_c = replay(CFilter(config), flight)
    state_err, cov_err = disagreement(trace_c, trace_ref)
    print(f"C vs reference, report timing ({options}, speed noise {speed_noise}): max |dx|/std = {state_err:.3g}, "
          f"max |dP_ii|/P_ii = {cov_err:.3g}")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL
    _, cov_off = disagreement(replay(CFilter(without), flight), trace_ref)
    assert cov_off > 10.0 * COV_TOL_REL


def test_quad_build_refuses_the_report_timing():
    """The quad build compiles no input error: a nonzero timing error is a configuration error naming it."""
    _, path = quad_library()
    with pytest.raises(UserError, match="bad rotor_timing_error"):
        CFilter(make_config().with_overrides(rotor_timing_error=0.002), library=path)
    CFilter(make_config().with_overrides(rotor_timing_error=0.0), library=path)


def check_quantised_against_reference(flight, config, without, label):
    """On the flight's speeds quantised to a 25 rad/s grid (values stand for several samples):
    C and the reference filter within the bounds with `config`, and C without the term under test
    (`without`) outside them (the comparison would see it missing on one side)."""
    quantised = [(t, kind, [25.0 * round(v / 25.0) for v in values] if kind == "rotor" else values)
                 for t, kind, values in flight]
    trace_ref = replay(ReferenceFilter(config), quantised)
    trace_c = replay(CFilter(config), quantised)
    state_err, cov_err = disagreement(trace_c, trace_ref)
    print(f"C vs reference, {label}: max |dx|/std = {state_err:.3g}, max |dP_ii|/P_ii = {cov_err:.3g}")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL
    _, cov_without = disagreement(replay(CFilter(without), quantised), trace_ref)
    assert cov_without > 10.0 * COV_TOL_REL


@pytest.mark.parametrize("options", ["plain", "all"])
@pytest.mark.parametrize("hold", [1, 2])
def test_c_agrees_with_reference_with_held_input_noise(flight, options, hold):
    """The input error's correlation time per rotor from how long its value has stood
    (rotor_speed_noise_hold, docs/math.md §14; 2: the configured time its floor): same bounds on
    the quantised flight, and the hold changes the run."""
    noisy = make_config(options).with_overrides(rotor_speed_noise=20.0, rotor_speed_noise_time=0.05)
    check_quantised_against_reference(flight, noisy.with_overrides(rotor_speed_noise_hold=hold), noisy,
                                      f"held input noise ({options}, hold {hold})")


@pytest.mark.parametrize("options", ["plain", "all"])
@pytest.mark.parametrize("hold", [0, 2])
def test_c_agrees_with_reference_with_split_input_noise(flight, options, hold):
    """The input error split into a truncation's mean, common to every rotor, and its spread
    per rotor, over the same spans (rotor_speed_noise_split, docs/math.md §14), with the configured
    time and with the hold as a floor: same bounds on the quantised flight, and the split changes
    the run."""
    independent = make_config(options).with_overrides(rotor_speed_noise=20.0, rotor_speed_noise_time=0.05,
                                                      rotor_speed_noise_hold=hold)
    check_quantised_against_reference(flight, independent.with_overrides(rotor_speed_noise_split=1),
                                      independent, f"split input noise ({options}, hold {hold})")


@pytest.mark.parametrize("options", ["plain", "all"])
@pytest.mark.parametrize("noise_time", [0.0, 0.05])
def test_c_agrees_with_reference_with_input_error_compensation(flight, options, noise_time):
    """The errors-in-variables compensation of the coefficient update (docs/math.md §14), white and
    correlated error: same bounds, and it moves the coefficients (the comparison would see it missing on
    one side)."""
    noisy = make_config(options).with_overrides(rotor_speed_noise=20.0, rotor_speed_noise_time=noise_time)
    config = noisy.with_overrides(input_error_compensation=1)
    trace_ref = replay(ReferenceFilter(config), flight)
    trace_c = replay(CFilter(config), flight)
    state_err, cov_err = disagreement(trace_c, trace_ref)
    _, x_off, _ = replay(CFilter(noisy), flight)[-1]
    moved = float(np.max(np.abs(trace_ref[-1][1][3:11] - x_off[3:11]) / np.sqrt(trace_ref[-1][2][3:11])))
    print(f"C vs reference, compensation ({options}, time {noise_time}): max |dx|/std = {state_err:.3g}, "
          f"max |dP_ii|/P_ii = {cov_err:.3g}; coefficients moved by up to {moved:.3g} std")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL
    assert moved > 10.0 * STATE_TOL_SIGMA


def with_stuck_gyro(events, axis: int, start_us: int, end_us: int, short_axis: int, short_at_us: int,
                    short_count: int):
    """The flight with gyro axis `axis` repeating its reading of `start_us` bit for bit up to `end_us`
    (a stuck sensor), and axis `short_axis` repeating one reading `short_count` times from
    `short_at_us` (a run shorter than the check's). Returns the events and the stuck samples."""
    out, held, stuck, short_left, short_value = [], None, 0, 0, None
    for t_us, kind, values in events:
        if kind == "gyro":
            values = list(values)
            if start_us <= t_us <= end_us:
                held = values[axis] if held is None else held
                values[axis] = held
                stuck += 1
            if t_us == short_at_us:
                short_left, short_value = short_count, values[short_axis]
            if short_left > 0:
                values[short_axis] = short_value
                short_left -= 1
        out.append((t_us, kind, values))
    return out, stuck


@pytest.mark.parametrize("options", ["plain", "all"])
def test_c_agrees_with_reference_with_the_stuck_gyro_check(flight, options):
    """gyro_stuck_samples (docs/reliability.md "A stuck gyro axis"): one axis stuck for 0.5 s, another
    repeating one reading 4 times (below K = 6): same bounds, the same count of axis-samples left out
    (the stuck run from its K-th sample on, none of the short run), and the check changes the run."""
    k = 6
    events, stuck = with_stuck_gyro(flight, axis=0, start_us=1_500_000, end_us=2_000_000,
                                    short_axis=1, short_at_us=1_700_000, short_count=4)
    assert stuck == 251
    config = make_config(options).with_overrides(gyro_stuck_samples=k)
    ref, c = ReferenceFilter(config), CFilter(config)
    trace_ref, trace_c = replay(ref, events), replay(c, events)
    state_err, cov_err = disagreement(trace_c, trace_ref)  # inf when any status differs
    print(f"C vs reference, stuck gyro ({options}): max |dx|/std = {state_err:.3g}, "
          f"max |dP_ii|/P_ii = {cov_err:.3g}")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL
    assert c.counters()["gyro_stuck"] == ref.counters()["gyro_stuck"] == stuck - k + 1
    _, cov_off = disagreement(replay(CFilter(make_config(options)), events), trace_ref)
    assert cov_off > 10.0 * COV_TOL_REL


def arriving(events, rotor_shift_us: int, offset_us: int = 10_000):
    """The flight as it arrives when the rotor telemetry is stamped rotor_shift_us late (> 0: the
    rotor speeds lag) or early (< 0: the gyro lags), in arrival order (rotor speeds first at equal
    stamps, otherwise the recorded order); every stamp moved by offset_us so that none is negative."""
    moved = [(t + offset_us + (rotor_shift_us if kind == "rotor" else 0), kind, values)
             for t, kind, values in events]
    return sorted(moved, key=lambda event: (event[0], event[1] != "rotor"))


@pytest.mark.parametrize("options", ["plain", "all"])
@pytest.mark.parametrize("delay_us", [6000, -6000])
def test_c_agrees_with_reference_with_a_telemetry_delay(flight, options, delay_us):
    """The delay buffer (docs/math.md §12): the flight with its rotor stamps moved by the delay,
    both filters configured with it; per push the same status and the same bounds. With the
    accelerometer ("all") the held IMU stream carries both sensors."""
    config = make_config(options).with_overrides(rotor_delay_us=delay_us)
    events = arriving(flight, delay_us)
    ref, c_filter = ReferenceFilter(config), CFilter(config)
    trace_ref, trace_c = replay(ref, events), replay(c_filter, events)
    statuses = [s for s, _, _ in trace_c]
    if delay_us > 0:
        assert statuses.count(STATUS["PROPID_OK_QUEUED"]) == len(statuses)
    else:
        assert STATUS["PROPID_OK_QUEUED"] not in statuses
    counters_c, counters_ref = c_filter.counters(), ref.counters()
    for name in ("gyro_accepted", "rotor_accepted", "accel_accepted", "delay_overflows", "rejected"):
        assert counters_c[name] == counters_ref[name], name
    assert counters_c["delay_overflows"] == 0 and not counters_c["rejected"]
    est_c, est_ref = c_filter.estimate(), ref.estimate()
    assert est_c.rotor_delay_us == est_ref.rotor_delay_us == delay_us
    assert est_c.model_terms == est_ref.model_terms == (0b11111 if options == "all" else 0b10000)
    assert counters_c["gyro_accepted"] >= 2490  # all but the last few held samples of 2500
    state_err, cov_err = disagreement(trace_c, trace_ref)
    print(f"C vs reference, delay {delay_us} us, {options}: max |dx|/std = {state_err:.3g}, "
          f"max |dP_ii|/P_ii = {cov_err:.3g}")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL


def states_by_fused_gyro(filt, events):
    """{number of gyro samples fused: scaled state right after that many} over a run."""
    states = {}
    for t_us, kind, values in events:
        if kind == "rotor":
            filt.push_rotor_speeds(t_us, values)
        elif kind == "gyro":
            filt.push_gyro(t_us, values)
        elif kind == "reset_rotor":
            filt.reset_rotor(values)
        count = filt.counters()["gyro_accepted"]
        if count not in states:
            states[count] = filt.scaled_state()[0]
    return states


def test_delay_compensates_a_shifted_stream(flight):
    """The reference with the delay configured, on the flight with shifted rotor stamps, passes
    through the states of the undelayed reference on the aligned flight (compared whenever it
    has fused as many gyro samples); without the delay configured it does not."""
    flight = [event for event in flight if event[1] in ("rotor", "gyro")]  # reset_rotor acts at once
    aligned = states_by_fused_gyro(ReferenceFilter(make_config()), arriving(flight, 0))
    for delay_us in (6000, -6000):
        for configured, expect_equal in ((delay_us, True), (0, False)):
            shifted = states_by_fused_gyro(ReferenceFilter(make_config().with_overrides(rotor_delay_us=configured)),
                                           arriving(flight, delay_us))
            common = sorted(set(shifted) & set(aligned))
            assert len(common) > 2400
            worst = max(float(np.max(np.abs(shifted[k] - aligned[k]))) for k in common)
            print(f"rotor stamps moved {delay_us} us, delay configured {configured}: max |dx| {worst:.3g}")
            assert (worst < 1e-9) == expect_equal


def with_commands(events, lead_us: int = 1000, full_speed: float = 1600.0):
    """The flight with a motor command (0..1, the commanded speed over full_speed) lead_us before each
    rotor sample."""
    out = []
    for t_us, kind, values in events:
        if kind == "rotor" and t_us >= lead_us:
            out.append((t_us - lead_us, "command", [min(v / full_speed, 1.0) for v in values]))
        out.append((t_us, kind, values))
    return out


@pytest.mark.parametrize("options", ["plain", "all"])
def test_c_agrees_with_reference_with_the_command_instrument(flight, options):
    """The motor commands' first stage (docs/math.md §16): same bounds, the fit takes over the rotor input
    (counted), and it changes the run (the comparison would see it missing on one side)."""
    events = with_commands(flight)
    config = make_config(options).with_overrides(motor_command_instrument=1, motor_command_lag=0.005,
                                                 motor_command_memory=2.0)
    c_filter, ref = CFilter(config), ReferenceFilter(config)
    trace_c, trace_ref = replay(c_filter, events), replay(ref, events)
    state_err, cov_err = disagreement(trace_c, trace_ref)
    print(f"C vs reference, command instrument ({options}): max |dx|/std = {state_err:.3g}, "
          f"max |dP_ii|/P_ii = {cov_err:.3g}")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL
    rotor_samples = sum(1 for _, kind, _ in flight if kind == "rotor")
    for counters in (c_filter.counters(), ref.counters()):
        assert counters["command_accepted"] == rotor_samples - 1
        assert counters["instrument_inputs"] == rotor_samples - 1 - 50  # all but the fit's first 50
    assert c_filter.counters()["instrument_inputs"] == ref.counters()["instrument_inputs"]
    off = replay(CFilter(make_config(options)), events)
    moved = max(float(np.max(np.abs(a[1] - b[1]) / np.sqrt(b[2]))) for a, b in zip(off, trace_ref))
    assert moved > 10.0 * STATE_TOL_SIGMA


def test_command_rejections_agree():
    """propid_push_motor_command's rejection codes are the same in both filters, and a rejected command
    leaves the first stage untouched."""
    on = make_config().with_overrides(motor_command_instrument=1)
    for filt in (CFilter(make_config()), ReferenceFilter(make_config())):
        assert filt.push_motor_command(1000, [0.5] * 4) == STATUS["PROPID_ERR_CONFIG"]
    c_filter, ref = CFilter(on), ReferenceFilter(on)
    for filt in (c_filter, ref):
        assert filt.push_motor_command(1000, [0.5] * 3) == STATUS["PROPID_ERR_ROTOR_COUNT"]
        assert filt.push_motor_command(1000, [0.5, math.nan, 0.5, 0.5]) == STATUS["PROPID_ERR_NOT_FINITE"]
        assert filt.push_motor_command(1000, [0.5, math.inf, 0.5, 0.5]) == STATUS["PROPID_ERR_NOT_FINITE"]
        assert filt.push_motor_command(1000, [0.5, 1.01, 0.5, 0.5]) == STATUS["PROPID_ERR_ROTOR_SPEED_RANGE"]
        assert filt.push_motor_command(1000, [0.5, -0.01, 0.5, 0.5]) == STATUS["PROPID_ERR_ROTOR_SPEED_RANGE"]
        assert filt.push_motor_command(1000, [0.5] * 4) == STATUS["PROPID_OK"]
        assert filt.push_motor_command(1000, [0.6] * 4) == STATUS["PROPID_ERR_TIME_BACKWARDS"]
        assert filt.push_motor_command(900, [0.6] * 4) == STATUS["PROPID_ERR_TIME_BACKWARDS"]
        assert filt.push_motor_command(2000, [0.6] * 4) == STATUS["PROPID_OK"]
        assert filt.counters()["command_accepted"] == 2
    assert c_filter.counters()["rejected"] == ref.counters()["rejected"]


def test_accel_rejections_agree(flight):
    """The accelerometer's rejection codes are the same in both filters."""
    for options, expected in (("plain", "PROPID_ERR_CONFIG"), ("all", None)):
        c_filter, ref = CFilter(make_config(options)), ReferenceFilter(make_config(options))
        for filt in (c_filter, ref):
            first = filt.push_accel(1000, [0.0, 0.0, 9.8])
            if expected:
                assert first == STATUS[expected]
                continue
            assert first == STATUS["PROPID_ERR_NO_ROTOR_DATA"]
            assert filt.push_rotor_speeds(1000, [900.0] * 4) == STATUS["PROPID_OK"]
            assert filt.push_accel(1000, [0.0, math.nan, 9.8]) == STATUS["PROPID_ERR_NOT_FINITE"]
            assert filt.push_accel(1000, [0.0, 0.0, 1e3]) == STATUS["PROPID_ERR_ACCEL_RANGE"]
            assert filt.push_accel(1000, [0.0, 0.0, 9.8]) == STATUS["PROPID_OK"]
            assert filt.push_accel(1000, [0.0, 0.0, 9.8]) == STATUS["PROPID_ERR_TIME_BACKWARDS"]
            assert filt.push_accel(10**6, [0.0, 0.0, 9.8]) == STATUS["PROPID_ERR_ROTOR_STALE"]
        assert c_filter.counters()["rejected"] == ref.counters()["rejected"]


def test_defaults_match_c():
    c_defaults = c_default_tuning()
    for name, value in DEFAULT_TUNING.items():
        assert c_defaults[name] == pytest.approx(value, rel=1e-6), name


def test_c_agrees_with_reference(flight, reference_trace):
    trace_c = replay(CFilter(make_config()), flight)
    assert len(trace_c) == len(reference_trace) > 2000
    statuses = [s for s, _, _ in trace_c]
    assert statuses.count(STATUS["PROPID_OK_GATED"]) == 3  # the three outliers
    state_err, cov_err = disagreement(trace_c, reference_trace)
    print(f"C vs reference: max |dx|/std = {state_err:.3g}, max |dP_ii|/P_ii = {cov_err:.3g}")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL


def quad_library():
    """The quad build (PROPID_QUAD_BUILD: 4 rotors, optional terms compiled out),
    built next to the full library (cmake target propid_quad_shared)."""
    path = library_path().with_name("libpropid_quad_shared.so")
    try:
        return load_library(path), path
    except UserError as exc:
        pytest.fail(str(exc))


def test_quad_build_agrees_with_reference(flight, reference_trace):
    lib, path = quad_library()
    assert lib.propid_max_rotors == 4 and lib.propid_max_states == 14
    trace_c = replay(CFilter(make_config(), library=path), flight)
    assert len(trace_c) == len(reference_trace)
    assert [s for s, _, _ in trace_c].count(STATUS["PROPID_OK_GATED"]) == 3
    state_err, cov_err = disagreement(trace_c, reference_trace)
    print(f"quad build vs reference: max |dx|/std = {state_err:.3g}, max |dP_ii|/P_ii = {cov_err:.3g}")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL


def test_size_lean_quad_build_agrees_with_reference(flight, reference_trace):
    """The size-lean quad build (PROPID_SIZE_LEAN: the quad build's kernels as
    loops, -Os; cmake target propid_quad_lean_shared) against the same reference."""
    path = library_path().with_name("libpropid_quad_lean_shared.so")
    try:
        lib = load_library(path)
    except UserError as exc:
        pytest.fail(str(exc))
    assert lib.propid_max_rotors == 4 and lib.propid_max_states == 14
    trace_c = replay(CFilter(make_config(), library=path), flight)
    assert len(trace_c) == len(reference_trace)
    assert [s for s, _, _ in trace_c].count(STATUS["PROPID_OK_GATED"]) == 3
    state_err, cov_err = disagreement(trace_c, reference_trace)
    print(f"size-lean quad build vs reference: max |dx|/std = {state_err:.3g}, "
          f"max |dP_ii|/P_ii = {cov_err:.3g}")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL


def test_quad_build_bits_match_row_groups(flight):
    """On a 64-bit desktop host the quad downdate sweeps P row by row in SIMD
    chunks (PROPID_HOST_ROW_SWEEP); the same build with the Cortex-M4's row groups
    in portable C instead (cmake target propid_quad_row_groups_shared,
    PROPID_NO_HOST_ROW_SWEEP) must give the same status, state and whole
    covariance, bit for bit, after every gyro sample of the flight (one changed
    operation in either kernel fails this)."""
    libraries = [library_path().with_name(name)
                 for name in ("libpropid_quad_shared.so", "libpropid_quad_row_groups_shared.so")]
    filters = []
    for path in libraries:
        try:
            load_library(path)
        except UserError as exc:
            pytest.fail(str(exc))
        filters.append(CFilter(make_config(), library=path))
    samples = 0
    for t_us, kind, values in flight:
        if kind == "rotor":
            statuses = [f.push_rotor_speeds(t_us, values) for f in filters]
        elif kind == "reset_rotor":
            statuses = [f.reset_rotor(values) for f in filters]
        elif kind == "gyro":
            statuses = [f.push_gyro(t_us, list(values)) for f in filters]
            (state_a, cov_a), (state_b, cov_b) = (f.scaled_state() for f in filters)
            assert state_a.tobytes() == state_b.tobytes(), f"state differs at t_us={t_us}"
            assert cov_a.tobytes() == cov_b.tobytes(), f"covariance differs at t_us={t_us}"
            samples += 1
        else:
            continue
        assert statuses[0] == statuses[1], f"{kind} status differs at t_us={t_us}"
    assert samples > 2000


def test_quad_build_rejects_compiled_out_options():
    _, path = quad_library()
    with pytest.raises(UserError, match="bad"):
        CFilter(make_config("all"), library=path)


def test_quad_build_refuses_aero_damping():
    """The quad build has no general step for the damping's rate entries: a nonzero value is a
    configuration error naming the field; zeros are the plain filter."""
    _, path = quad_library()
    with pytest.raises(UserError, match="bad aero_damping"):
        CFilter(make_config().with_overrides(aero_damping=[0.0, 0.0, 1e-3]), library=path)
    CFilter(make_config().with_overrides(aero_damping=[0.0, 0.0, 0.0]), library=path)


def test_quad_build_refuses_the_command_instrument():
    """The quad build compiles the first stage out: the option is a configuration error, a command is
    refused with PROPID_ERR_CONFIG."""
    _, path = quad_library()
    with pytest.raises(UserError, match="bad motor_command_instrument"):
        CFilter(make_config().with_overrides(motor_command_instrument=1), library=path)
    filt = CFilter(make_config(), library=path)
    assert filt.push_motor_command(1000, [0.5] * 4) == STATUS["PROPID_ERR_CONFIG"]
    assert filt.counters()["command_accepted"] == 0


def test_disagreement_is_detected(flight, reference_trace):
    """The comparison can fail: one gyro sample off by 0.01 rad/s (about one
    noise std) in the C run only must exceed the tolerance."""
    gyro_times = [t for t, kind, _ in flight if kind == "gyro"]
    trace_c = replay(CFilter(make_config()), flight, perturb_at=gyro_times[len(gyro_times) // 2])
    state_err, _ = disagreement(trace_c, reference_trace)
    assert state_err > 5 * STATE_TOL_SIGMA


def test_reference_converges(flight, reference_trace):
    """The reference itself identifies the coefficients (guards against two
    identical wrong implementations agreeing)."""
    ref = ReferenceFilter(make_config())
    replay(ref, flight)
    est = ref.estimate()
    rng = np.random.default_rng(7)
    kf_true = 5.57e-6 * (1.0 + rng.uniform(-0.2, 0.2, 4))
    km_true = 1.36e-7 * (1.0 + rng.uniform(-0.2, 0.2, 4))
    assert np.all(np.abs(est.thrust_coeff / kf_true - 1.0) < 0.03)
    assert np.all(np.abs(est.drag_coeff / km_true - 1.0) < 0.06)
    assert np.all(np.abs(est.thrust_coeff - kf_true) < 4.0 * est.thrust_coeff_std)


@pytest.mark.parametrize("options", ["plain", "all"])
def test_c_agrees_with_reference_on_the_bounds(flight, options):
    """Coefficients riding their bounds (docs/math.md §15): the range narrowed to +-10 % of
    nominal on a flight whose coefficients are off by up to 20 %, so thrust and drag coefficients
    are projected onto a bound at many samples; same bounds, the same number of clamps."""
    config = make_config(options).with_overrides(coeff_rel_min=0.9, coeff_rel_max=1.1)
    ref, c_filter = ReferenceFilter(config), CFilter(config)
    trace_ref, trace_c = replay(ref, flight), replay(c_filter, flight)
    clamps = c_filter.counters()["state_clamps"]
    state_err, cov_err = disagreement(trace_c, trace_ref)
    print(f"C vs reference on the bounds ({options}): {clamps} clamps, max |dx|/std = {state_err:.3g}, "
          f"max |dP_ii|/P_ii = {cov_err:.3g}")
    assert clamps > 100
    # The C filter also counts crossings by its float32 reflections' rounding.
    assert abs(clamps - ref.counters()["state_clamps"]) <= 0.02 * clamps
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL


def test_c_agrees_with_reference_with_the_weak_instrument_guard(flight):
    """The first stage's weak-instrument guard (motor_command_min_f, docs/math.md §16): with the last
    rotor's command unrelated to its speed (white), C and the reference leave that rotor (about all its samples
    after the fit's first 50) to its telemetry, by the same count, and agree within the usual bounds."""
    rng = np.random.default_rng(7)
    events = []
    for t_us, kind, values in with_commands(flight):
        if kind == "command":  # the last rotor's command: white, independent of every speed
            values = list(values[:-1]) + [float(rng.uniform(0.4, 0.8))]
        events.append((t_us, kind, values))
    config = make_config().with_overrides(motor_command_instrument=1, motor_command_lag=0.005,
                                          motor_command_memory=2.0, motor_command_min_f=10.0)
    c_filter, ref = CFilter(config), ReferenceFilter(config)
    trace_c, trace_ref = replay(c_filter, events), replay(ref, events)
    state_err, cov_err = disagreement(trace_c, trace_ref)
    guarded_c, guarded_ref = c_filter.counters()["instrument_guarded"], ref.counters()["instrument_guarded"]
    rotor_samples = sum(1 for _, kind, _ in flight if kind == "rotor")
    print(f"C vs reference, weak-instrument guard: max |dx|/std = {state_err:.3g}, max |dP_ii|/P_ii = "
          f"{cov_err:.3g}; guarded C {guarded_c}, reference {guarded_ref} of {rotor_samples} rotor samples")
    assert state_err < STATE_TOL_SIGMA
    assert cov_err < COV_TOL_REL
    assert abs(guarded_c - guarded_ref) <= max(2, guarded_ref // 100)
    assert guarded_ref >= 0.9 * (rotor_samples - 1 - 50)
    assert c_filter.counters()["instrument_inputs"] < guarded_ref  # the last rotor never from the fit
