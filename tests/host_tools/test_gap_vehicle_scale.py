"""The corrected vehicle file's torque scale (gap/vehicle_out.py): the file is read by the firmware
filter, which takes the logged rotor speeds without an instrument, so it carries inertia_error's
least-squares scale (attenuation included), not the instrument's that the base fit uses."""

import numpy as np
import pytest

from propid.flightlog import parse_vehicle
from propid.gap import basefit
from propid.gap.calibration import base_fit_with_calibrated_inertia
from propid.gap.prep import Band, prepare_flight
from propid.gap.vehicle_out import corrected_vehicle
from propid.replay import ReplayOptions, replay
from test_replay import KF_TRUE, VEHICLE
from test_replay_instrument import TOP_SPEED, commanded_log


def _inertia_error(params: dict) -> dict:
    return {"id": "inertia_error", "significant": True, "params": params}


def test_the_file_carries_the_least_squares_scale():
    vehicle = parse_vehicle(VEHICLE)
    j = np.diag(np.asarray(vehicle.inertia, dtype=float))
    params = {"inertia_scale_xx": 1.10, "inertia_scale_yy": 1.05,
              "inertia_scale_xx_least_squares": 1.30, "inertia_scale_yy_least_squares": 1.20}
    out, carried = corrected_vehicle(vehicle, [_inertia_error(params)])
    assert np.diag(np.asarray(out.inertia)) == pytest.approx(j * [1.30, 1.20, 1.0])
    assert carried["applied"]["inertia_error"]["scale_source"] == "least squares"
    # without motor commands there is one scale, the effect's fit
    out, carried = corrected_vehicle(vehicle, [_inertia_error({"inertia_scale_xx": 1.10, "inertia_scale_yy": 1.05})])
    assert np.diag(np.asarray(out.inertia)) == pytest.approx(j * [1.10, 1.05, 1.0])
    assert carried["applied"]["inertia_error"]["scale_source"].startswith("the effect's fit")


def test_the_calibrated_after_fit_uses_the_file_scale_over_the_fit_scale():
    after = {"kf_thrust": {"value": 1.0, "ci": [0.9, 1.1]}, "kf_roll": {"value": 1.0, "ci": [0.9, 1.1]},
             "kf_pitch": {"value": 2.0, "ci": [1.8, 2.2]}}
    out = base_fit_with_calibrated_inertia(after, 1.1, {"kf_roll": 1.2})
    assert out["kf_roll"]["value"] == pytest.approx(1.1 * 1.2)
    assert out["kf_roll"]["ci"] == pytest.approx([0.9 * 1.32, 1.1 * 1.32])
    assert out["kf_pitch"]["value"] == pytest.approx(2.2)
    assert out["kf_thrust"] is after["kf_thrust"]


def test_noisy_rotor_speeds_the_least_squares_file_lifts_the_gyro_only_filter(cfilter_available):
    """Telemetry with 0.5 % white noise attenuates the gyro-only filter (kf 0.77 of the truth with the true
    inertia). The scales as gap's fits give them against a noise-free thrust reference (the rotors' mean kf):
    least squares and the instrument in 2-25 Hz. The file with the least-squares scale lifts the filter
    (0.845), the instrument's does not (0.790): the instrument removes the band fit's attenuation, which
    the filter, fed the noisy speeds, still has. Only part of it: the filter sees the white error over the
    whole band, the 2-25 Hz fit a share of it."""
    log = commanded_log(0.005)
    vehicle = parse_vehicle(VEHICLE)
    flight = prepare_flight(log, vehicle, Band(2.0, 25.0))
    reference = float(np.mean(KF_TRUE))
    params = {}
    for axis, key in (("roll", "inertia_scale_xx"), ("pitch", "inertia_scale_yy")):
        fit = basefit.fleet_fit([flight], axis, vehicle.positions, vehicle.yaw_signs, None)
        assert fit["method"].startswith("instrumental")
        params[key] = reference / fit["value"]
        params[key + "_least_squares"] = reference / fit["least_squares_value"]
    options = ReplayOptions(progress=False, aiding="gyro", max_rotor_speed=TOP_SPEED)

    def filter_kf(v) -> float:
        return float(np.mean(np.array(replay(log, v, options).summary["kf_mean"]) / KF_TRUE))

    as_is = filter_kf(vehicle)
    least_squares = filter_kf(corrected_vehicle(vehicle, [_inertia_error(params)])[0])
    instrument_only = dict(params)
    for key in ("inertia_scale_xx", "inertia_scale_yy"):
        instrument_only.pop(key + "_least_squares")
    instrument = filter_kf(corrected_vehicle(vehicle, [_inertia_error(instrument_only)])[0])
    print(f"gyro-only kf / truth: file {as_is:.3f}, instrument's scale {instrument:.3f}, "
          f"least-squares scale {least_squares:.3f}")
    assert as_is < 0.85
    assert abs(instrument - as_is) < 0.05  # the instrument's scale is about the true inertia here
    assert least_squares > instrument + 0.04
    assert least_squares < 1.0  # part of the attenuation, not more
