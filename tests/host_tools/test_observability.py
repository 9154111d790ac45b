"""Lie-derivative observability (propid.observability): known ranks and unseen directions."""

from __future__ import annotations

import json
import math
from fractions import Fraction

import pytest

from propid import observability
from propid.cli import main
from propid.errors import UserError
from propid.flightlog import parse_vehicle


def vehicle_dict(count: int, first_angle: float, inertia=(1.43e-5, 1.43e-5, 2.89e-5),
                 arm: float = 0.043, centre_rotor: int | None = None) -> dict:
    rotors = []
    for i in range(count):
        angle = first_angle + 2.0 * math.pi * i / count
        position = [round(arm * math.cos(angle), 12), round(arm * math.sin(angle), 12), 0.0]
        if centre_rotor == i:
            position = [0.0, 0.0, 0.0]
        rotors.append({"position": position, "yaw_sign": 1 if i % 2 == 0 else -1})
    return {"name": f"test-{count}", "mass": 0.03, "inertia": list(inertia), "rotors": rotors,
            "kf_nominal": 2.3e-8, "km_nominal": 7.8e-10}


def analyse(data: dict, measurements=("gyro",)) -> observability.Result:
    return observability.analyse(parse_vehicle(data), measurements)


def null_contains(result: observability.Result, direction: dict[str, int]) -> bool:
    """Is the direction in the span of the hover null space? (rank test over Q)"""
    vector = [Fraction(direction.get(name, 0)) for name in result.state_names]
    space = observability.RowSpace(result.n)
    for row in result.hover_null_space:
        space.add(row)
    before = space.rank
    space.add(vector)
    return space.rank == before


def test_plus_quad_from_the_gyro_is_full_rank_at_second_order():
    result = analyse(vehicle_dict(4, 0.0))
    assert result.n == 14
    assert result.generic_rank == 14 and result.observable
    # Jxx = Jyy: the first-order derivatives (the paper's eq. 2) give 13, the
    # second order separates the yaw rate from the z bias
    assert result.rank_by_order == [3, 13, 14]


def test_plus_quad_at_hover_sees_differences_not_sums():
    result = analyse(vehicle_dict(4, 0.0))
    assert result.hover_rank == 6
    assert len(result.hover_null_space) == 8
    assert null_contains(result, {"kf_1": 1, "kf_3": 1})
    assert null_contains(result, {"kf_2": 1, "kf_4": 1})
    assert not null_contains(result, {"kf_1": 1, "kf_3": -1})
    assert null_contains(result, {"omega_z": 1, "b_z": -1})
    assert not null_contains(result, {"km_1": 1, "km_2": -1, "km_3": 1, "km_4": -1})
    assert "km_1 - km_2 + km_3 - km_4" in result.hover_seen_combinations()
    assert result.hover_observable_states() == []


def test_accelerometer_adds_the_collective_thrust_at_hover():
    result = analyse(vehicle_dict(4, 0.0), ("gyro", "accel"))
    assert result.generic_rank == 14
    assert result.hover_rank == 7
    assert not null_contains(result, {"kf_1": 1, "kf_2": 1, "kf_3": 1, "kf_4": 1})
    assert null_contains(result, {"kf_1": 1, "kf_2": -1, "kf_3": 1, "kf_4": -1})


@pytest.mark.parametrize("count,first_angle", [(4, math.pi / 4), (6, 0.0), (6, math.pi / 6),
                                               (8, 0.0), (8, math.pi / 8)])
def test_other_geometries_are_full_rank_and_hover_rank_six(count, first_angle):
    result = analyse(vehicle_dict(count, first_angle))
    assert result.n == 6 + 2 * count
    assert result.generic_rank == result.n
    assert result.hover_rank == 6
    assert null_contains(result, {"kf_1": 1, f"kf_{count // 2 + 1}": 1})  # opposite rotors


def test_rotor_at_the_centre_of_mass_has_unobservable_thrust():
    result = analyse(vehicle_dict(4, 0.0, centre_rotor=0))
    assert result.generic_rank == 13
    assert not result.observable
    assert result.hover_rank is None  # pitch torque needs the lone -x rotor stopped


def test_spherical_inertia_hides_the_gyro_biases():
    # no gyroscopic coupling: the bias is never separated from the rate
    result = analyse(vehicle_dict(4, 0.0, inertia=(2e-5, 2e-5, 2e-5)))
    assert result.generic_rank == 11


def test_describe_direction_is_sign_normalised():
    names = ["a", "b", "c"]
    assert observability.describe_direction(names, [Fraction(-1), Fraction(0), Fraction(2)]) == "a - 2 c"
    assert observability.describe_direction(names, [Fraction(0), Fraction(1, 2), Fraction(1, 2)]) == "b + c"


def test_geometry_rounding_is_not_a_direction():
    """A plus quad's arms as propid_sitl writes them (L cos 90 deg = 2.6e-18 m, not 0) read as the exact plus
    quad: 'kf_1 - kf_3', not 'kf_1 + 6.12e-17 kf_2 - 1 kf_3 - 1.84e-16 kf_4'."""
    names = ["a", "b", "c"]
    assert observability.describe_direction(
        names, [Fraction(1.0), Fraction(6.12e-17), Fraction(-0.9999999999999998)]) == "a - c"
    assert observability.describe_direction(names, [Fraction(1), Fraction(1, 1000), Fraction(0)]) == "a + 0.001 b"
    exact = analyse(vehicle_dict(4, 0.0))
    unrounded = vehicle_dict(4, 0.0)
    for i, rotor in enumerate(unrounded["rotors"]):
        angle = 2.0 * math.pi * i / 4
        rotor["position"] = [0.043 * math.cos(angle), 0.043 * math.sin(angle), 0.0]
    assert unrounded["rotors"][1]["position"][0] != 0.0
    floats = analyse(unrounded)
    def hover_part(result):  # what is seen and not seen at hover
        text = observability.render_text(result)
        return text[text.index("at hover"):]

    assert floats.generic_rank == exact.generic_rank and hover_part(floats) == hover_part(exact)
    assert "kf_1 - kf_3" in floats.hover_seen_combinations()


def test_cli_prints_and_writes_json(tmp_path, capsys):
    path = tmp_path / "quad.json"
    path.write_text(json.dumps(vehicle_dict(4, math.pi / 4)))
    out_json = tmp_path / "obs.json"
    assert main(["observability", "--vehicle", str(path), "--json", str(out_json)]) == 0
    text = capsys.readouterr().out
    assert "14 of 14" in text and "locally weakly observable" in text
    data = json.loads(out_json.read_text())
    assert data["generic_rank"] == 14 and data["hover_rank"] == 6
    assert "kf_1 + kf_3" in data["hover_unobservable_directions"]


def test_cli_bad_inputs_one_line_errors(tmp_path, capsys):
    path = tmp_path / "quad.json"
    data = vehicle_dict(4, 0.0)
    path.write_text(json.dumps(data))
    assert main(["observability", "--vehicle", str(path), "--measure", "accel"]) == 1
    assert main(["observability", "--vehicle", str(path), "--measure", "gyro,magnetometer"]) == 1
    del data["inertia"]
    path.write_text(json.dumps(data))
    assert main(["observability", "--vehicle", str(path)]) == 1
    (tmp_path / "broken.json").write_text("{not json")
    assert main(["observability", "--vehicle", str(tmp_path / "broken.json")]) == 1
    errors = capsys.readouterr().err.strip().splitlines()
    assert len(errors) == 4 and all(line.startswith("propid observability: error:") for line in errors)


def test_analyse_rejects_unknown_measurements():
    with pytest.raises(UserError):
        analyse(vehicle_dict(4, 0.0), ("sonar",))
