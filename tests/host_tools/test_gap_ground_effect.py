"""propid gap's ground_effect regressor at each rotor's hub height (docs/gap.md, Effect library):
the hub heights follow the attitude, and on a SITL flight near the ground the roll/pitch
columns and the thrust column read the same ground gain."""

from __future__ import annotations

import subprocess
from types import SimpleNamespace

import numpy as np
import pytest

from propid.flightlog import read_flightlog, read_vehicle


def _flight(quat, height=0.1, n=1):
    from propid.gap.prep import Band, Flight

    n = n if quat is None else len(quat)
    zeros = np.zeros((n, 3))
    return Flight(name="t", path=None, rate_hz=100.0, t=np.arange(n) / 100.0, gyro=zeros, rate_dot=zeros,
                  speed=np.full((n, 4), 2000.0), speed_dot=np.zeros((n, 4)), torque=zeros,
                  specific_force_z=None, acc=None, body_velocity=None, height=np.full(n, height), cmd=None,
                  vbat=None, segs=[(0, n)], band=Band(), quat=None if quat is None else np.asarray(quat, float))


def _context(positions):
    from propid.gap.effects import Context

    n = len(positions)
    return Context(positions=np.asarray(positions, float), yaw_signs=np.array([1.0, -1.0, 1.0, -1.0])[:n],
                   kf=np.full(n, 1e-8), km=np.full(n, 1e-10), mass=0.03, inertia=np.eye(3) * 1e-5,
                   rotor_radius=0.02, speed_ref=2000.0)


def test_hub_heights_follow_the_attitude():
    """Rolled by phi (body FLU, quaternion body -> world), a hub at +y rises by y sin(phi), one
    at +x stays; pitched by theta, a hub at +x sinks by x sin(theta); without an attitude every
    hub is at the logged height."""
    from propid.gap.effects import hub_heights

    positions = [[0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [-0.05, 0.0, 0.0], [0.0, -0.05, 0.01]]
    phi, theta = 0.2, 0.3
    roll = [np.cos(phi / 2), np.sin(phi / 2), 0.0, 0.0]
    pitch = [np.cos(theta / 2), 0.0, np.sin(theta / 2), 0.0]
    c = _context(positions)
    rolled = hub_heights(_flight([roll]), c)[0]
    assert rolled == pytest.approx([0.1, 0.1 + 0.05 * np.sin(phi), 0.1,
                                    0.1 - 0.05 * np.sin(phi) + 0.01 * np.cos(phi)], abs=1e-12)
    pitched = hub_heights(_flight([pitch]), c)[0]
    assert pitched == pytest.approx([0.1 - 0.05 * np.sin(theta), 0.1, 0.1 + 0.05 * np.sin(theta),
                                     0.1 + 0.01 * np.cos(theta)], abs=1e-12)
    assert hub_heights(_flight(None), c)[0] == pytest.approx([0.1] * 4)


def test_ground_effect_roll_pitch_and_thrust_columns_read_the_same_gain(tmp_path, sitl_binary):
    """SITL ground_effect=2 (Cheeseman-Bennett gain x2 at each hub's height) on a Lissajous
    flight 0.1 m above the ground (about 4 rotor radii): the gain fitted on roll and pitch
    alone (the tilt's restoring torque: the lower rotors gain more) and on thrust alone (on top
    of the base model, its per-rotor kf/km refitted) both read about 2. With the CoM height for
    every rotor the roll/pitch fit reads about 8: that torque was missing from the regressor and
    a torque-scale look-alike took it up (the blind benchmark named thrust_nonlinearity)."""
    from propid.gap import effects, scoring
    from propid.gap.analysis import make_context
    from propid.gap.design import build_design
    from propid.gap.prep import Band, prepare_flight

    log_path = tmp_path / "ground.csv"
    subprocess.run([str(sitl_binary), "--quiet", "--mode", "incorrect", "--vehicle", "crazyflie-plus",
                    "--seed", "999714649", "--duration", "12", "--log-rate", "500", "--esc-rate", "100",
                    "--esc-latency", "0", "--esc-phase", "0", "--trajectory", "lissajous",
                    "--trajectory-period", "9.554", "--yaw-amplitude", "0.9631", "--yaw-cycles", "0.5197",
                    "--start-height", "0.1055", "--effect", "ground_effect=2", "--log", str(log_path)],
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120, check=True)
    vehicle = read_vehicle(log_path.with_name(log_path.stem + ".vehicle.json"))
    log = read_flightlog(log_path, vehicle)
    assert prepare_flight(log, vehicle, Band()).quat is None  # the default: pz for every rotor

    def gains(f):
        ones = np.ones(vehicle.rotor_count)
        base = build_design([f], make_context([f], vehicle, ones, ones), [], vehicle.mass, True)
        theta = scoring.solve(scoring.grams(base), base.groups["base"], np.arange(base.n_blocks))
        theta = theta / base.scale[base.groups["base"]]
        ctx = make_context([f], vehicle, theta[:vehicle.rotor_count], theta[vehicle.rotor_count:])
        design = build_design([f], ctx, [effects.by_id("ground_effect")], vehicle.mass, True)
        gr = scoring.grams(design)
        cols = design.groups["base"] + design.groups["ground_effect"]
        out = {}
        for axes in (("roll", "pitch"), ("thrust",)):
            only = np.array([1.0 if a in axes else 0.0 for a in design.axes])
            gr.weight = only * scoring.axis_weights(design, design.groups["base"])
            out[axes] = scoring.solve(gr, cols, np.arange(design.n_blocks))[-1] / design.scale[cols[-1]]
        return out

    hub = gains(prepare_flight(log, vehicle, Band(), attitude=True))
    assert hub[("roll", "pitch")] == pytest.approx(2.0, rel=0.3)
    assert hub[("thrust",)] == pytest.approx(2.0, rel=0.3)
    com = gains(prepare_flight(log, vehicle, Band()))
    assert com[("roll", "pitch")] > 4.0
    assert com[("thrust",)] == pytest.approx(2.0, rel=0.3)


@pytest.mark.parametrize("height,attitude", [("com", False), ("hub", True)])
def test_the_option_reaches_the_data_preparation(height, attitude, monkeypatch):
    """analysis.Options.ground_effect_height (the CLI's --ground-effect-height) decides whether the
    flights keep their attitude, i.e. whether ground_effect is taken at each hub."""
    from propid.gap import analysis
    from propid.gap.prep import Band

    seen = []

    class Stop(Exception):
        pass

    def record(log, vehicle, band, name=None, repeats="samples", attitude=False, gyro_bias="off"):
        seen.append(attitude)
        raise Stop

    monkeypatch.setattr(analysis, "prepare_flight", record)
    monkeypatch.setattr(analysis, "canonical_order", lambda logs: list(logs))
    vehicle = SimpleNamespace(inertia=np.eye(3))
    with pytest.raises(Stop):
        analysis.run([object()], vehicle, [], analysis.Options(Band(), progress=False, ground_effect_height=height))
    assert seen == [attitude]
