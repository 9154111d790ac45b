"""Metamorphic checks of `propid gap`: a copy of a flight that means the same thing (rotors relabelled
with the vehicle file, the mirror image across the body x-z plane, a clock that starts at 1e6 s) gives
the same diagnosis (docs/gap.md, "What does not change the diagnosis")."""

from __future__ import annotations

import json
import subprocess

import numpy as np

from propid.flightlog import FlightLog, read_flightlog, write_flightlog
from propid.gap.whitening import whitening_gain

SPEC_COLUMNS = ("acc_x", "acc_y", "acc_z", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "px", "py", "pz")


def test_the_whitening_region_does_not_depend_on_the_last_bit_of_the_rate():
    # A 2 Hz high-pass puts the full-gain region's edge at 2.5 Hz, a bin of the 0.5 Hz grid of 2 s windows.
    # A median step of 0.0100000001 s (what a clock origin at 1e6 s gives a 100 Hz log) used to drop that bin,
    # and every effect's held-out fraction moved with it.
    rng = np.random.default_rng(3)
    residual = [np.cumsum(rng.normal(size=3000)) * 0.01 + rng.normal(size=3000)]
    freqs, gain = whitening_gain(residual, 100.0, (2.0, 25.0))
    for rate in (100.0 * (1 - 1e-9), 100.0 * (1 + 1e-9)):
        freqs_r, gain_r = whitening_gain(residual, rate, (2.0, 25.0))
        np.testing.assert_allclose(freqs_r, freqs, rtol=1e-8)
        np.testing.assert_allclose(gain_r, gain, rtol=1e-6)


def _relabelled_mirrored_late(log: FlightLog, vehicle: dict, perm: list[int]) -> tuple[FlightLog, dict]:
    """The same flight: rotor j of the copy is rotor perm[j]; reflected across the x-z plane (rotor y and
    spin flip; rates -M w: x, z flip; vectors M v: y flips; attitude M R M = (w, -x, y, -z)); stamped from
    1e6 s."""
    extra = {k: np.array(log.extra[k]) for k in SPEC_COLUMNS if k in log.extra}
    for key in ("acc_y", "vy", "py", "qx", "qz"):
        extra[key] = -extra[key]
    copy = FlightLog(t=log.t + 1.0e6, gyro=log.gyro * [-1.0, 1.0, -1.0], rotor_speed=log.rotor_speed[:, perm],
                     extra=extra)
    mirrored = json.loads(json.dumps(vehicle))  # a deep copy: the original stays as it is
    mirrored["rotors"] = [mirrored["rotors"][p] for p in perm]
    for rotor in mirrored["rotors"]:
        rotor["position"][1] = -rotor["position"][1]
        rotor["yaw_sign"] = -rotor["yaw_sign"]
    for key in ("kf_nominal", "km_nominal", "rotor_inertia"):
        if isinstance(vehicle.get(key), list):
            mirrored[key] = [vehicle[key][p] for p in perm]
    return copy, mirrored


def test_gap_gives_the_same_diagnosis_of_the_relabelled_mirrored_late_copy(tmp_path, sitl_binary):
    from propid.cli import main

    original = tmp_path / "flight.csv"
    subprocess.run([str(sitl_binary), "--quiet", "--duration", "8", "--seed", "3", "--log", str(original),
                    "--effect", "rotor_inertia=2"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   timeout=120, check=True)
    vehicle = json.loads(original.with_name("flight.vehicle.json").read_text())
    log = read_flightlog(original)
    log = FlightLog(t=log.t, gyro=log.gyro, rotor_speed=log.rotor_speed,
                    extra={k: log.extra[k] for k in SPEC_COLUMNS if k in log.extra})
    copy, copy_vehicle = _relabelled_mirrored_late(log, vehicle, [2, 0, 3, 1])
    results = []
    for name, flight, vehicle_dict in (("a", log, vehicle), ("b", copy, copy_vehicle)):
        write_flightlog(tmp_path / f"{name}.csv", flight)
        (tmp_path / f"{name}.vehicle.json").write_text(json.dumps(vehicle_dict))
        out = tmp_path / f"{name}.json"
        assert main(["gap", "--log", str(tmp_path / f"{name}.csv"), "--json", str(out), "--no-filter",
                     "--no-progress"]) == 0
        results.append(json.loads(out.read_text()))
    first, second = results
    assert first["verdict"] != "none"  # a diagnosis that can change
    assert second["verdict"] == first["verdict"]
    assert [e["id"] for e in second["effects"] if e["significant"]] == [e["id"] for e in first["effects"]
                                                                         if e["significant"]]
    assert second["untestable"] == first["untestable"]
    fractions = {e["id"]: e["explained_fraction"] for e in first["effects"]}
    for effect in second["effects"]:
        assert abs(effect["explained_fraction"] - fractions[effect["id"]]) < 1e-6, effect["id"]
    for key, fit in first["base_fit"].items():
        if fit is not None:
            assert abs(second["base_fit"][key]["value"] / fit["value"] - 1) < 1e-6, key


def test_the_events_layout_carries_the_rotor_streams_copies():
    # gap flagged a copy of the previous rotor row on the log's own rows, then kept the gyro rows only: on an
    # events log every rotor copy was dropped with its row, so the stream-quality report read 0 % (a SITL
    # flight's sample-and-held telemetry: 53.5 % on the rows log) and --repeats missing interpolated none.
    from propid.flightlog import parse_vehicle
    from propid.gap.prep import Band, prepare_flight
    from test_gap_repeats import with_lost_packets
    from test_replay import VEHICLE, synthetic_log
    from test_replay_metamorphic import events_layout

    lossy, _, rotor_rows = with_lost_packets(synthetic_log(duration=20.0, rate=100.0, seed=7), seed=107)
    vehicle = parse_vehicle(VEHICLE)
    for repeats in ("samples", "missing"):
        rows = prepare_flight(lossy, vehicle, Band(), name="log", repeats=repeats)
        events = prepare_flight(events_layout(lossy), vehicle, Band(), name="log", repeats=repeats)
        assert rows.repeated_rows["rotor"]["count"] > 0.3 * len(lossy.t)
        assert events.repeated_rows == rows.repeated_rows
        np.testing.assert_array_equal(events.t, rows.t)
        np.testing.assert_allclose(events.speed, rows.speed, rtol=1e-12)
        np.testing.assert_allclose(events.torque, rows.torque, rtol=1e-12, atol=1e-15)
