"""Map a flight controller's motor numbering onto the vehicle file's rotor order.

Flight controllers number motors by their mixer (Betaflight QUADX: 1 rear-right,
2 front-right, 3 rear-left, 4 front-left; PX4 quad X: 1 front-right, 2 rear-left,
3 front-left, 4 rear-right). The vehicle file orders rotors however its author chose.
For a quad X both are matched by quadrant of the rotor position (body FLU); an
explicit map overrides the guess.
"""

from __future__ import annotations

import numpy as np

from propid.errors import UserError
from propid.flightlog import Vehicle

# Quadrant (sign of x forward, sign of y left) of each motor, in the controller's numbering.
BETAFLIGHT_QUADX = [(-1, -1), (+1, -1), (-1, +1), (+1, +1)]
PX4_QUADX = [(+1, -1), (-1, +1), (+1, +1), (-1, -1)]


def parse_motor_map(text: str, rotor_count: int) -> list[int]:
    """'2,1,4,3' -> [1, 0, 3, 2]: vehicle rotor i is the controller's motor map[i] (1-based in text)."""
    try:
        values = [int(v) for v in text.split(",")]
    except ValueError:
        raise UserError(f"--motor-map {text!r}: expected comma-separated motor numbers, e.g. 1,2,3,4") from None
    if sorted(values) != list(range(1, rotor_count + 1)):
        raise UserError(f"--motor-map {text!r}: must list each of the motors 1..{rotor_count} exactly once")
    return [v - 1 for v in values]


def quadrant_map(vehicle: Vehicle | None, layout: list[tuple[int, int]], motor_count: int) -> tuple[list[int], str]:
    """Controller motor index for each vehicle rotor, and how it was decided."""
    identity = list(range(motor_count))
    if vehicle is None:
        return identity, "no vehicle file: motors kept in the controller's order"
    if vehicle.rotor_count != motor_count:
        raise UserError(
            f"the log has {motor_count} motors but the vehicle file {vehicle.path or ''} has {vehicle.rotor_count} rotors"
        )
    if motor_count != len(layout):
        return identity, "not a quad: motors kept in the controller's order (give --motor-map to change)"
    pos = vehicle.positions
    quadrants = [(int(np.sign(p[0])), int(np.sign(p[1]))) for p in pos]
    if sorted(quadrants) != sorted(layout) or len(set(quadrants)) != len(layout):
        return identity, "vehicle is not a quad X: motors kept in the controller's order (give --motor-map to change)"
    mapping = [layout.index(q) for q in quadrants]
    return mapping, "matched by quadrant: vehicle rotor i <- motor " + ",".join(str(m + 1) for m in mapping)
