"""gap's firmware-filter check replays with every model key the vehicle file carries,
the way `propid replay` takes them (docs/gap.md, "How far")."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from propid.gap import filtercheck


class _Result:
    summary = {"kf_mean": [3.0e-8, 3.2e-8]}


def test_filter_check_carries_the_files_model_keys(monkeypatch):
    seen = []

    def fake_replay(log, vehicle, options):
        seen.append((log, options))
        return _Result()

    monkeypatch.setattr("propid.replay.replay", fake_replay)
    log = SimpleNamespace(path="log.csv")
    kf = filtercheck._replay_kf(log, object.__new__(_Vehicle), "default")
    assert np.isclose(kf, 3.1e-8)
    (passed_log, options), = seen
    assert passed_log is log  # the gyro is not rescaled here: the replay undoes gyro_scale at its boundary
    assert options.rotor_inertia == "auto"
    assert options.aero_damping == "auto"
    assert options.gyro_scale == "auto"
    assert options.aiding == "gyro" and options.torque_scale == "off" and options.disturbance == "off"
    assert not options.skip_repeats
    # filter_before_after skips the logger's repeated rows unless told not to
    seen.clear()
    filtercheck.filter_before_after([log], object.__new__(_Vehicle), object.__new__(_Vehicle))
    assert [options.skip_repeats for _, options in seen] == [True, True]
    seen.clear()
    filtercheck.filter_before_after([log], object.__new__(_Vehicle), object.__new__(_Vehicle), skip_repeats=False)
    assert [options.skip_repeats for _, options in seen] == [False, False]


class _Vehicle:
    loop_bandwidth_hz = None
    gyro_scale = [1.05, 1.0, 1.0]
