"""propid gap: the torque gain per band (basefit.torque_gain_per_band) on a synthetic closed loop whose truth
is known: a cascaded attitude / rate controller flying a broadband reference, with and without a slow torque
disturbance that the loop answers."""

from __future__ import annotations

import numpy as np
import pytest

from propid.flightlog import FlightLog, Rotor, Vehicle
from propid.gap import basefit
from propid.gap.prep import Band, prepare_flight

KF, KM, ARM, MASS = 3e-8, 7e-10, 0.035, 0.035
INERTIA = np.array([1.7e-5, 1.7e-5, 3e-5])
POSITIONS = np.array([[ARM, -ARM, 0], [-ARM, -ARM, 0], [-ARM, ARM, 0], [ARM, ARM, 0]]) / np.sqrt(2)
YAW_SIGNS = np.array([-1, 1, -1, 1.0])
ALLOCATION = np.vstack([np.full(4, KF), POSITIONS[:, 1] * KF, -POSITIONS[:, 0] * KF, YAW_SIGNS * KM])
MOTOR_LAG = 0.02
TOP_SPEED = 3500.0


def _shaped_noise(rng, n, rate, rms, lo=None, hi=None, corner=None):
    spectrum = np.fft.rfft(rng.standard_normal(n))
    freq = np.fft.rfftfreq(n, 1 / rate)
    if corner is not None:  # first-order low-pass: a slow disturbance with a tail
        spectrum = spectrum / (1 + 1j * freq / corner)
        spectrum[freq < 0.1] = 0
    else:
        spectrum[(freq < lo) | (freq > hi)] = 0
    y = np.fft.irfft(spectrum, n)
    return y * rms / y.std()


def cascade_flight(disturbance_rms: float, seed: int = 1, rate: float = 100.0, duration: float = 40.0,
                   attitude_hz: float = 2.0, rate_loop_hz: float = 10.0) -> tuple[FlightLog, Vehicle]:
    """An X quad under a cascade: attitude P (attitude_hz; 0: none, a rate loop alone) -> rate PI
    (rate_loop_hz) -> rotor speeds (20 ms motor lag, logged commands); a broadband reference torque (0.3-30 Hz) the rotors follow, and a slow roll /
    pitch disturbance torque (first order, 1 Hz corner) they answer; telemetry with 0.5 % white noise."""
    rng = np.random.default_rng(seed)
    n = int(duration * rate)
    reference = np.column_stack([_shaped_noise(rng, n, rate, 6e-5, lo=0.3, hi=30.0) for _ in range(2)])
    disturbance = np.column_stack([_shaped_noise(rng, n, rate, disturbance_rms, corner=1.0) for _ in range(2)]) \
        if disturbance_rms else np.zeros((n, 2))
    k_att, k_rate = 2 * np.pi * attitude_hz, 2 * np.pi * rate_loop_hz
    k_int = k_rate * k_rate / 8
    substeps = 4
    h = 1.0 / (rate * substeps)
    alloc_inv = np.linalg.inv(ALLOCATION)
    omega, attitude, integral = np.zeros(3), np.zeros(3), np.zeros(2)
    speed = None
    speeds, commands, rates, acc = np.empty((n, 4)), np.empty((n, 4)), np.empty((n, 3)), np.empty(n)
    for k in range(n):
        rates[k] = omega
        error = -k_att * attitude[:2] - omega[:2]  # k_att 0: the rate loop alone
        integral += error / rate
        torque_cmd = np.zeros(3)
        torque_cmd[:2] = reference[k] + INERTIA[:2] * (k_rate * error + k_int * integral)
        torque_cmd[2] = -INERTIA[2] * k_rate * omega[2]
        command = np.sqrt(np.clip(alloc_inv @ np.concatenate([[MASS * 9.81], torque_cmd]), 1.0, None))
        speed = command.copy() if speed is None else speed
        speeds[k], commands[k] = speed, command
        for _ in range(substeps):
            speed = command + (speed - command) * np.exp(-h / MOTOR_LAG)
            wrench = ALLOCATION @ speed**2
            omega = omega + (wrench[1:] + np.array([*disturbance[k], 0.0])) / INERTIA * h
            attitude = attitude + omega * h
        acc[k] = (ALLOCATION @ speed**2)[0] / MASS
    extra = {"acc_x": np.zeros(n), "acc_y": np.zeros(n), "acc_z": acc + 0.05 * rng.standard_normal(n),
             "is_flying": np.ones(n), **{f"cmd_{i + 1}": np.clip(commands[:, i] / TOP_SPEED, 0, 1) for i in range(4)}}
    log = FlightLog(t=np.arange(n) / rate, gyro=rates + 2e-4 * rng.standard_normal((n, 3)),
                    rotor_speed=speeds * (1 + 0.005 * rng.standard_normal(speeds.shape)), extra=extra)
    vehicle = Vehicle(name="synthetic-cascade", rotors=[Rotor(tuple(p), int(s)) for p, s in zip(POSITIONS, YAW_SIGNS)],
                      mass=MASS, inertia=np.diag(INERTIA))
    return log, vehicle


def _gain(log, vehicle):
    flight = prepare_flight(log, vehicle, Band(1.0))
    return basefit.torque_gain_per_band([flight], vehicle.positions, vehicle.yaw_signs, vehicle.mass, thrust_kf=KF)


def _row(rows, lo):
    return next(r for r in rows if r["band_hz"][0] == pytest.approx(lo, rel=1e-6))


def test_a_disturbance_the_loop_answers_reads_as_a_gain_rising_through_the_truth():
    # the band fit's closed-loop bias: low below the loop's reach, ABOVE the truth where the lagged rate loop
    # amplifies the disturbance (0.16 at 2-2.8 Hz, 1.1 at 8-11 Hz, 1.4 at 11-16 Hz here), phase within 15 deg
    gain = _gain(*cascade_flight(1.5e-4))
    assert gain["method"].startswith("instrumental")
    for axis in ("roll", "pitch"):
        rows = gain[axis]
        assert [r["band_hz"][0] for r in rows[:3]] == pytest.approx([1.0, 2**0.5, 2.0])
        assert rows[-1]["band_hz"][1] <= 25.0
        assert _row(rows, 2.0)["ci"][1] < 0.5 * KF
        assert max(r["ci"][0] for r in rows if 8.0 <= r["band_hz"][0] < 16.0) > 1.0 * KF
        assert all(abs(r["phase_deg"]) < 20 for r in rows if r["band_hz"][0] >= 2.0)
        assert rows[0]["over_thrust"] == pytest.approx(rows[0]["value"] / KF)


def test_without_the_disturbance_the_bands_the_reference_excites_read_the_truth():
    # 0.88-1.01 of the truth in 4-16 Hz; below 4 Hz the attitude loop leaves the rotors little reference
    # content (wide intervals), and the top band reads 0.8-0.9 (low, not high: no rise)
    gain = _gain(*cascade_flight(0.0))
    for axis in ("roll", "pitch"):
        for r in gain[axis]:
            if 4.0 <= r["band_hz"][0] < 16.0:
                assert r["value"] == pytest.approx(KF, rel=0.15), r
        assert gain[axis][-1]["value"] < 1.0 * KF


def test_a_rate_loop_alone_peaks_above_the_truth_just_above_its_crossover_and_returns_far_above_it():
    # 2 Hz rate loop: 0.56 at 2-2.8 Hz (phase -60 deg), 1.4-1.7 at 5.7-8 Hz (phase -15..-22 deg), 0.93-0.96 at
    # 16-22.6 Hz: a lower band edge raised "until the fit stops rising" stops on the peak, not on the truth
    gain = _gain(*cascade_flight(1.5e-4, attitude_hz=0.0, rate_loop_hz=2.0))
    for axis in ("roll", "pitch"):
        rows = gain[axis]
        peak = _row(rows, 4 * 2**0.5)
        assert peak["ci"][0] > 1.0 * KF and peak["phase_deg"] < -10
        assert _row(rows, 2.0)["ci"][1] < 0.8 * KF and _row(rows, 2.0)["phase_deg"] < -30
        assert rows[-1]["ci"][0] < KF < rows[-1]["ci"][1]


def test_without_commands_the_gain_is_least_squares_and_short_logs_give_none():
    log, vehicle = cascade_flight(1.5e-4, duration=40.0)
    bare = FlightLog(t=log.t, gyro=log.gyro, rotor_speed=log.rotor_speed,
                     extra={k: v for k, v in log.extra.items() if not k.startswith("cmd_")})
    gain = _gain(bare, vehicle)
    assert gain["method"] == "least squares" and gain["windows"] == 10
    short = FlightLog(t=log.t[:2000], gyro=log.gyro[:2000], rotor_speed=log.rotor_speed[:2000],
                      extra={k: v[:2000] for k, v in log.extra.items()})
    assert _gain(short, vehicle) is None  # 20 s: 5 windows of 4 s, fewer than GAIN_MIN_WINDOWS
