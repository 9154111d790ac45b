"""Vehicle files for the synthetic flights of the host-tool tests (imported by them; not a
test module)."""

from __future__ import annotations


def x_quad(name: str, mass: float, inertia: list[float], arm: float, kf: float, km: float) -> dict:
    """A vehicle-file dict of an X quad: rotor i at (+-arm, +-arm, 0), front right first and
    counter-clockwise, yaw signs alternating from -1; nominal kf and km on every rotor."""
    return {
        "name": name,
        "mass": mass,
        "inertia": inertia,
        "rotors": [
            {"position": [arm, -arm, 0.0], "yaw_sign": -1},
            {"position": [-arm, -arm, 0.0], "yaw_sign": 1},
            {"position": [-arm, arm, 0.0], "yaw_sign": -1},
            {"position": [arm, arm, 0.0], "yaw_sign": 1},
        ],
        "kf_nominal": kf,
        "km_nominal": km,
    }
