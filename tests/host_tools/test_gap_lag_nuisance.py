"""propid gap --lag-nuisance shifted: the stream alignment's nuisance columns built at each candidate
lag from the rotor stream shifted by it (alignment.delay_designs `nuisance_at`), as every column is
after the alignment. rotor_gyroscopic, rotor_drag and com_offset are functions of the rotor speeds;
built once from the logged stream (the default) they carry the unshifted stream into every lag's fit,
and a constant gyro bias b puts b x (sum_i s_i Omega_i), an unshifted copy of the yaw rotor stream,
into rotor_gyroscopic's column: on the 100 Hz 50 ms-lag flight of test_gap.py the whitened lag
evidence then depends on whether the bias is removed (docs/gap.md "Stream alignment")."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from propid.errors import UserError
from propid.flightlog import read_flightlog, read_vehicle
from propid.gap import alignment, analysis
from propid.gap.prep import Band, prepare_flight

# test_gap.py's LONG_LAG_FLIGHTS["100Hz"]: a blind-benchmark flight with a 50 ms telemetry lag
FLIGHT = ("--quiet --mode incorrect --duration 12 --esc-latency 0 --esc-phase 0 --trajectory circle "
          "--effect esc_delay=0.05 --vehicle crazyflie-x --seed 43412613 --log-rate 100 --esc-rate 100 "
          "--trajectory-period 9.48 --yaw-amplitude 1.353 --yaw-cycles 1.547 --start-height 1.322 "
          "--gyro-bias-walk 0.00033907 --gyro-noise 0.000733038 --accel-noise 0.00514849 --esc-dropout 0.03")


@pytest.fixture(scope="module")
def lag_flight(tmp_path_factory, sitl_binary):
    path = tmp_path_factory.mktemp("lag_nuisance") / "lag.csv"
    subprocess.run([str(sitl_binary), "--log", str(path), *FLIGHT.split()], stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL, timeout=120, check=True)
    vehicle = read_vehicle(path.with_name(path.stem + ".vehicle.json"))
    return read_flightlog(path, vehicle), vehicle


def test_nuisance_columns_at_a_lag_are_those_of_the_shifted_stream(lag_flight):
    """Wiring: with nuisance_at, lag d's design carries the nuisance columns of the flight whose rotor
    stream is shifted by d (and at d = 0 exactly the logged ones); the default keeps the logged ones."""
    log, vehicle = lag_flight
    f = prepare_flight(log, vehicle, Band(highpass_hz=0.2))
    ctx = analysis.make_context([f], vehicle, np.ones(4), np.ones(4))
    candidates = list(analysis.ALIGNMENT_NUISANCE)
    logged = [analysis._alignment_nuisance(f, ctx, candidates)]
    shifted_at = analysis._nuisance_at([f], ctx, candidates, "shifted")
    grid = np.array([0.0, 0.04])
    by_default = alignment.delay_designs([f], vehicle.positions, vehicle.yaw_signs, grid, logged)
    by_lag = alignment.delay_designs([f], vehicle.positions, vehicle.yaw_signs, grid, logged, shifted_at)
    n_extra = logged[0]["roll"].shape[1]
    assert n_extra >= 4  # rotor_gyroscopic, rotor_drag (2 on roll/pitch at least), com_offset, aero_damping
    for a in ("roll", "pitch"):
        np.testing.assert_array_equal(by_lag[0].x[a], by_default[0].x[a])
        np.testing.assert_array_equal(by_lag[1].x[a][:, :-n_extra], by_default[1].x[a][:, :-n_extra])
        np.testing.assert_array_equal(by_default[1].x[a][:, -n_extra:], by_default[0].x[a][:, -n_extra:])
        expected = alignment.delay_designs([analysis.shifted_flight(f, 0.04)], vehicle.positions, vehicle.yaw_signs,
                                           np.array([0.0]), [analysis._alignment_nuisance(
                                               analysis.shifted_flight(f, 0.04), ctx, candidates)])[0]
        got = by_lag[1].x[a][:, -n_extra:] * by_lag[1].scale[-n_extra:]
        want = expected.x[a][:, -n_extra:] * expected.scale[-n_extra:]
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12 * np.abs(want).max())
        assert np.abs(got - by_default[1].x[a][:, -n_extra:] * by_default[1].scale[-n_extra:]).max() > \
            1e-3 * np.abs(want).max()


def test_with_shifted_nuisance_the_lag_evidence_does_not_depend_on_a_constant_gyro_bias(lag_flight):
    """The same flight with its gyro bias (measured against the attitude, 5.5 / 10.0 / -2.9 mrad/s)
    kept or removed: with the nuisance built per lag the lag, every fold's lag and the whitened
    evidence agree; the logged nuisance columns let the bias move one fold's lag by 10 ms there
    (docs/gap.md)."""
    log, vehicle = lag_flight
    out = {}
    for bias in ("off", "attitude"):
        result = analysis.run([log], vehicle, [], analysis.Options(
            Band(), progress=False, auto_highpass=True, lag_evidence="whitened", gyro_bias=bias,
            lag_nuisance="shifted"))
        assert result["alignment"]["nuisance"] == "shifted"
        out[bias] = result
    assert out["attitude"]["gyro_bias"]["per_log"][str(log.path)]["applied"]
    a, b = out["off"]["alignment"], out["attitude"]["alignment"]
    assert a["delay_s"] == pytest.approx(b["delay_s"], abs=2e-4)
    assert a["delay_s"] == pytest.approx(0.05, abs=0.006)
    assert a["whitened"]["fold_delays_s"] == b["whitened"]["fold_delays_s"]
    assert a["whitened"]["explained_fraction"] == pytest.approx(b["whitened"]["explained_fraction"], abs=0.01)
    assert out["off"]["verdict"] == out["attitude"]["verdict"] == "esc_delay"


def test_an_unknown_lag_nuisance_mode_is_refused(lag_flight):
    log, vehicle = lag_flight
    with pytest.raises(UserError, match="lag_nuisance"):
        analysis.run([log], vehicle, [], analysis.Options(Band(), progress=False, lag_nuisance="both"))
    assert analysis.Options(Band()).lag_nuisance == "logged"
