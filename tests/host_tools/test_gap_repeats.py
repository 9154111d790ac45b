"""`propid gap` and the logger's repeated rows (docs/gap.md "Data preparation", "Stream quality"): a row
whose gyro triple (rotor speeds) equals the previous row's bit for bit is a copy of a lost packet, not a
sample. gap reports the copies per log and stream; its firmware-filter check skips them (`--skip-repeats`);
`--repeats missing` (evaluated, not the default) treats them as missing samples in its fits."""

from __future__ import annotations

import numpy as np

from propid.flightlog import FlightLog, parse_vehicle
from propid.gap import analysis
from propid.gap.filtercheck import filter_before_after
from propid.gap.prep import Band, prepare_flight
from test_replay import KF_TRUE, KM_TRUE, VEHICLE, synthetic_log

GYRO_SHARE, ROTOR_SHARE = 0.27, 0.41  # random2_run1 of the Crazyflie logs


def with_lost_packets(log: FlightLog, seed: int) -> tuple[FlightLog, np.ndarray, np.ndarray]:
    """Each stream's packets lost independently (the gyro and the rotor speeds are separate log blocks);
    a lost one is written as a copy of the previous row's values."""
    rng = np.random.default_rng(seed)
    gyro, speeds = log.gyro.copy(), log.rotor_speed.copy()
    copied = []
    for values, share in ((gyro, GYRO_SHARE), (speeds, ROTOR_SHARE)):
        rows = np.sort(rng.choice(np.arange(1, len(log.t)), int(share * len(log.t)), replace=False))
        for k in rows:
            values[k] = values[k - 1]
        copied.append(rows)
    return FlightLog(t=log.t, gyro=gyro, rotor_speed=speeds, extra={}), copied[0], copied[1]


def _run(log: FlightLog, repeats: str) -> dict:
    result = analysis.run([log], parse_vehicle(VEHICLE), [],
                          analysis.Options(Band(), progress=False, auto_highpass=True, repeats=repeats))
    result.pop("_internal")
    return result


def _base_fit(result: dict) -> np.ndarray:
    fit = result["base_fit"]
    return np.array([fit["kf_roll"]["value"] / np.mean(KF_TRUE), fit["kf_pitch"]["value"] / np.mean(KF_TRUE),
                     fit["km_yaw"]["value"] / np.mean(KM_TRUE)])


def test_a_log_without_copies_gives_the_same_result_either_way():
    clean = synthetic_log(duration=20.0, rate=100.0, seed=7)
    missing, samples = _run(clean, "missing"), _run(clean, "samples")
    quality = missing["stream_quality"]["repeated_rows"]
    assert quality["per_log"]["log"]["gyro"] == {"share": 0.0, "count": 0, "longest_run": 0}
    assert quality["per_log"]["log"]["rotor"]["count"] == 0 and quality["logs_above_5_percent"] == []
    assert samples["stream_quality"]["repeated_rows"]["treated_as"] == "samples"
    for result in (missing, samples):
        del result["stream_quality"]
    assert repr(missing) == repr(samples)  # every figure, bit for bit


def test_copies_are_reported_and_treated_as_missing_samples():
    clean = synthetic_log(duration=40.0, rate=100.0, seed=7)
    lossy, gyro_rows, rotor_rows = with_lost_packets(clean, seed=107)
    vehicle = parse_vehicle(VEHICLE)
    flight = prepare_flight(lossy, vehicle, Band(), repeats="missing")
    # the synthetic log's NaN rotor rows are never copies (NaN equals nothing)
    nan_copies = int(np.sum(~np.isfinite(lossy.rotor_speed[rotor_rows]).all(axis=1)))
    assert flight.repeated_rows["gyro"]["count"] == gyro_rows.size  # every row of this log flies
    assert flight.repeated_rows["rotor"]["count"] == rotor_rows.size - nan_copies
    assert flight.repeated_rows["gyro"]["share"] == gyro_rows.size / len(lossy.t)
    # a copy is replaced by the interpolation of its neighbours, never kept as logged
    inner = gyro_rows[(gyro_rows < len(lossy.t) - 1)]
    inner = inner[~np.isin(inner + 1, gyro_rows)]
    assert np.all(flight.gyro[inner] != lossy.gyro[inner])
    kept = prepare_flight(lossy, vehicle, Band(), repeats="samples")
    np.testing.assert_array_equal(kept.gyro, lossy.gyro)


def test_copies_as_missing_bring_the_torque_kf_back_to_the_truth():
    """Known truth (the synthetic rate-loop flight, lost packets as on random2_run1): the roll/pitch torque kf
    of the base fit with the copies fused against treated as missing (both sides of the fit interpolated
    across every row a copy leaves unmeasured). Printed by this test: kf_roll, kf_pitch / truth per seed."""
    for seed in (7, 8):
        clean = synthetic_log(duration=40.0, rate=100.0, seed=seed)
        lossy, _, _ = with_lost_packets(clean, seed=100 + seed)
        fused = _base_fit(_run(lossy, "samples"))
        missing_result = _run(lossy, "missing")
        missing = _base_fit(missing_result)
        print(f"seed {seed}: fused {fused.round(4)}, missing {missing.round(4)} (kf_roll, kf_pitch, km_yaw / truth)")
        assert np.sum(np.abs(missing[:2] - 1.0)) < np.sum(np.abs(fused[:2] - 1.0))
        assert np.all(np.abs(missing[:2] - 1.0) < 0.015)
        assert missing_result["stream_quality"]["repeated_rows"]["logs_above_5_percent"] == ["log"]


def test_the_filter_check_skips_the_copies(cfilter_available):
    """The firmware filter check replays with --skip-repeats: the copies fused read kf low (docs/real-data.md
    "Repeated rows"), skipped they do not."""
    clean = synthetic_log(duration=40.0, rate=100.0, seed=7)
    lossy, _, _ = with_lost_packets(clean, seed=107)
    vehicle = parse_vehicle(VEHICLE)
    truth = float(np.mean(KF_TRUE))
    skipped = filter_before_after([lossy], vehicle, vehicle)
    fused = filter_before_after([lossy], vehicle, vehicle, skip_repeats=False)
    assert skipped["skip_repeats"] and not fused["skip_repeats"]
    kf_skipped = skipped["kf_before"]["mean"] / truth
    kf_fused = fused["kf_before"]["mean"] / truth
    assert abs(kf_skipped - 1.0) < abs(kf_fused - 1.0)
    assert abs(kf_skipped - 1.0) < 0.03
