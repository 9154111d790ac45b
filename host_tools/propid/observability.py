"""Nonlinear observability of the filter's model: Lie-derivative rank, symbolically.

The model is the filter's (docs/math.md section 1), in control-affine form with
the rotor speeds squared ``u_i`` as inputs::

    x = [omega (3), kf_rel (N), km_rel (N), b_g (3)]
    dx/dt = f_0(x) + sum_i f_i(x) u_i
    f_0 = [-J^-1 (omega x J omega); 0],   f_i = [a_i kf_rel_i + d_i km_rel_i; 0]

with ``a_i = J^-1 (r_i x z) kf_nominal_i`` and ``d_i = J^-1 z yaw_sign_i km_nominal_i``.
Measurements: the gyro ``h = omega + b_g``; optionally the accelerometer's
specific force along body z, ``sum_i u_i kf_nominal_i kf_rel_i / m`` (thrust only,
IMU at the centre of mass). That output is affine in the input, so, as for the
dynamics, each ``g_i = kf_nominal_i kf_rel_i / m`` counts as an output function.

The observability codistribution (Hermann & Krener) is spanned by the gradients of
the outputs and of their repeated Lie derivatives along f_0..f_N. Every function
is a polynomial with exact rational coefficients (the vehicle's numbers are read
as exact decimals), built with sympy; the rank of the stacked gradients is
computed in exact rational arithmetic at random rational points (the generic
rank: the rank almost everywhere), level by level until a level adds nothing.

At hover the input is constant (the torque-free allocation of a collective
thrust) and the rates are zero: only Lie derivatives along the single drift
field ``F = f_0 + sum_i u_hover_i f_i`` exist, evaluated at that point. Their null
space is what the measurements cannot see there; it is reported as a basis of
directions in state space.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field
from fractions import Fraction

import sympy

from propid.errors import UserError
from propid.flightlog import Vehicle

MEASUREMENTS = ("gyro", "accel")
MAX_ORDER_DEFAULT = 4
NEGLIGIBLE_WEIGHT = 1e-9  # of a printed direction, relative: a nanometre on a metre arm


def _exact(value: float) -> sympy.Rational:
    """A float read as the exact decimal it prints as (2.3e-08 -> 23/10^9)."""
    return sympy.Rational(repr(float(value)))


@dataclass
class Model:
    """The filter's model of one vehicle as sympy polynomials."""

    state_names: list[str]
    symbols: list[sympy.Symbol]
    drift: list[sympy.Poly]            # f_0, one Poly per rate component
    rotor_fields: list[list[sympy.Poly]]  # f_i, i = 1..N, rate components
    gyro: list[sympy.Poly]             # omega + b_g
    accel_terms: list[sympy.Poly]      # g_i = kf_nominal_i kf_rel_i / m
    thrust_torque: list[list[sympy.Rational]]  # a_i
    drag_torque: list[list[sympy.Rational]]    # d_i
    kf_nominal: list[sympy.Rational]

    @property
    def n(self) -> int:
        return len(self.symbols)

    @property
    def rotor_count(self) -> int:
        return len(self.rotor_fields)


def build_model(vehicle: Vehicle) -> Model:
    """The control-affine model of ``vehicle`` (inertia and nominal coefficients required)."""
    where = str(vehicle.path) if vehicle.path else (vehicle.name or "vehicle")
    if vehicle.inertia is None:
        raise UserError(f"{where}: the observability analysis needs 'inertia'")
    if vehicle.kf_nominal is None or vehicle.km_nominal is None:
        raise UserError(f"{where}: the observability analysis needs 'kf_nominal' and 'km_nominal'")
    count = vehicle.rotor_count
    names = (["omega_x", "omega_y", "omega_z"]
             + [f"kf_{i}" for i in range(1, count + 1)]
             + [f"km_{i}" for i in range(1, count + 1)]
             + ["b_x", "b_y", "b_z"])
    syms = list(sympy.symbols(" ".join(names)))
    omega = sympy.Matrix(syms[0:3])
    kf = syms[3:3 + count]
    km = syms[3 + count:3 + 2 * count]
    bias = syms[3 + 2 * count:]

    inertia = sympy.Matrix(3, 3, [_exact(v) for v in vehicle.inertia.reshape(-1)])
    inertia = (inertia + inertia.T) / 2
    inertia_inv = inertia.inv()
    z_axis = sympy.Matrix([0, 0, 1])
    kf_nom = [_exact(v) for v in vehicle.kf_nominal]
    km_nom = [_exact(v) for v in vehicle.km_nominal]
    mass = _exact(vehicle.mass) if vehicle.mass else sympy.Integer(1)

    def poly(expr) -> sympy.Poly:
        return sympy.Poly(sympy.expand(expr), *syms, domain="QQ")

    gyroscopic = -inertia_inv * omega.cross(inertia * omega)
    drift = [poly(gyroscopic[k]) for k in range(3)]
    fields, thrust_dirs, drag_dirs = [], [], []
    for i, rotor in enumerate(vehicle.rotors):
        position = sympy.Matrix([_exact(p) for p in rotor.position])
        a_i = inertia_inv * position.cross(z_axis) * kf_nom[i]
        d_i = inertia_inv * z_axis * (rotor.yaw_sign * km_nom[i])
        thrust_dirs.append(list(a_i))
        drag_dirs.append(list(d_i))
        fields.append([poly(a_i[k] * kf[i] + d_i[k] * km[i]) for k in range(3)])
    gyro = [poly(omega[k] + bias[k]) for k in range(3)]
    accel = [poly(kf_nom[i] * kf[i] / mass) for i in range(count)]
    return Model(names, syms, drift, fields, gyro, accel, thrust_dirs, drag_dirs, kf_nom)


def lie_derivative(model: Model, function: sympy.Poly, rate_field: list[sympy.Poly]) -> sympy.Poly:
    """L_f phi = grad(phi) . f for a field that moves only the three rates."""
    out = sympy.Poly(0, *model.symbols, domain="QQ")
    for k in range(3):
        out += function.diff(model.symbols[k]) * rate_field[k]
    return out


# --------------------------------------------------------------------------- exact rank
class RowSpace:
    """Incremental row echelon basis over the rationals (exact rank)."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.pivots: dict[int, list[Fraction]] = {}  # pivot column -> row with 1 there

    @property
    def rank(self) -> int:
        return len(self.pivots)

    def add(self, row: list[Fraction]) -> bool:
        """Reduce ``row`` by the basis; keep it if independent. True if the rank grew."""
        row = list(row)
        for col in range(self.n):
            if row[col] == 0:
                continue
            basis = self.pivots.get(col)
            if basis is None:
                scale = row[col]
                self.pivots[col] = [v / scale for v in row]
                self._normalise_others(col)
                return True
            factor = row[col]
            row = [r - factor * b for r, b in zip(row, basis)]
        return False

    def _normalise_others(self, col: int) -> None:
        new = self.pivots[col]
        for other_col, other in self.pivots.items():
            if other_col != col and other[col] != 0:
                factor = other[col]
                self.pivots[other_col] = [o - factor * v for o, v in zip(other, new)]

    def null_space(self) -> list[list[Fraction]]:
        """A basis of the vectors orthogonal to every row (one per free column)."""
        basis = []
        for free in range(self.n):
            if free in self.pivots:
                continue
            vector = [Fraction(0)] * self.n
            vector[free] = Fraction(1)
            for col, row in self.pivots.items():
                vector[col] = -row[free]
            basis.append(vector)
        return basis


def _gradient_at(model: Model, function: sympy.Poly, point: dict) -> list[Fraction]:
    values = []
    for sym in model.symbols:
        value = function.diff(sym).eval(point) if function.degree(sym) > 0 else 0
        rational = sympy.Rational(value)
        values.append(Fraction(int(rational.p), int(rational.q)))
    return values


def _random_point(model: Model, rng: random.Random) -> dict:
    """A random rational state: rates ~ 1 rad/s, coefficients ~ 1 (relative), biases small."""
    point = {}
    for name, sym in zip(model.state_names, model.symbols):
        if name.startswith("omega"):
            point[sym] = sympy.Rational(rng.randint(-1000, 1000), 997)
        elif name.startswith("b_"):
            point[sym] = sympy.Rational(rng.randint(-100, 100), 9973)
        else:
            point[sym] = sympy.Rational(rng.randint(800, 1200), 1000)
    return point


# --------------------------------------------------------------------------- analyses
@dataclass
class Result:
    vehicle: str
    measurements: tuple[str, ...]
    state_names: list[str]
    generic_rank: int
    rank_by_order: list[int]
    functions_by_order: list[int]
    hover_input: list[float]
    hover_rank: int | None  # None: no torque-free hover with positive speeds
    hover_rank_by_order: list[int]
    hover_null_space: list[list[Fraction]] = field(default_factory=list)
    hover_row_space: list[list[Fraction]] = field(default_factory=list)

    @property
    def n(self) -> int:
        return len(self.state_names)

    @property
    def observable(self) -> bool:
        return self.generic_rank == self.n

    def hover_seen_combinations(self) -> list[str]:
        return [describe_direction(self.state_names, row) for row in self.hover_row_space]

    def hover_observable_states(self) -> list[str]:
        """States whose unit direction is orthogonal to every unseen direction at hover."""
        if self.hover_rank is None:
            return []
        return [name for j, name in enumerate(self.state_names)
                if all(vector[j] == 0 for vector in self.hover_null_space)]

    def to_json(self) -> dict:
        return {
            "vehicle": self.vehicle,
            "measurements": list(self.measurements),
            "states": self.state_names,
            "n": self.n,
            "generic_rank": self.generic_rank,
            "locally_weakly_observable": self.observable,
            "rank_by_order": self.rank_by_order,
            "functions_by_order": self.functions_by_order,
            "hover_input_rel": self.hover_input,
            "hover_rank": self.hover_rank,
            "hover_rank_by_order": self.hover_rank_by_order,
            "hover_unobservable_directions": [describe_direction(self.state_names, v)
                                              for v in self.hover_null_space],
            "hover_seen_combinations": self.hover_seen_combinations(),
            "hover_observable_states": self.hover_observable_states(),
        }


def _dedupe(functions: list[sympy.Poly], seen: set) -> list[sympy.Poly]:
    out = []
    for function in functions:
        if function.is_zero or function.total_degree() == 0:
            continue
        key = function.as_expr()
        if key in seen or -key in seen:
            continue
        seen.add(key)
        out.append(function)
    return out


def generic_rank(model: Model, measurements: tuple[str, ...], max_order: int,
                 points: int = 2, seed: int = 1, progress=None) -> tuple[list[int], list[int]]:
    """Rank of the codistribution of Lie derivatives up to each order (all inputs free).

    Returns (rank after each order, number of distinct functions at each order).
    Stops early when a whole order adds no rank (the codistribution is then
    invariant under every field) or when the rank is full.
    """
    rng = random.Random(seed)
    spaces = [RowSpace(model.n) for _ in range(points)]
    state_points = [_random_point(model, rng) for _ in range(points)]
    level = list(model.gyro) if "gyro" in measurements else []
    if "accel" in measurements:
        level += list(model.accel_terms)
    seen: set = set()
    level = _dedupe(level, seen)
    fields = [model.drift] + model.rotor_fields
    ranks, counts = [], []
    for order in range(max_order + 1):
        for function in level:
            for space, point in zip(spaces, state_points):
                space.add(_gradient_at(model, function, point))
        ranks.append(max(space.rank for space in spaces))
        counts.append(len(level))
        if progress:
            progress(order, ranks[-1])
        if ranks[-1] == model.n or (order > 0 and ranks[-1] == ranks[-2]) or order == max_order:
            break
        level = _dedupe([lie_derivative(model, function, rate_field)
                         for function in level for rate_field in fields], seen)
    return ranks, counts


def hover_input(model: Model) -> list[sympy.Rational] | None:
    """Torque-free rotor speeds squared of minimum norm, scaled so their mean is 1.

    The solution of B u = (collective, 0, 0, 0) with B the nominal wrench map
    (thrust row kf_nominal_i; torque rows a_i + d_i); only its direction matters
    for the rank.
    """
    count = model.rotor_count
    rows = [[model.kf_nominal[i] for i in range(count)]]
    for k in range(3):
        rows.append([model.thrust_torque[i][k] + model.drag_torque[i][k] for i in range(count)])
    wrench = sympy.Matrix(rows)
    # drop dependent rows (a coaxial or degenerate layout) before the pseudo-inverse
    independent = wrench.T.columnspace()
    wrench = sympy.Matrix.hstack(*independent).T
    target = sympy.zeros(wrench.rows, 1)
    target[0] = 1
    speeds = wrench.T * (wrench * wrench.T).inv() * target
    mean = sum(speeds) / count
    if any(value <= 0 for value in speeds):
        return None
    return [value / mean for value in speeds]


def hover_rank(model: Model, measurements: tuple[str, ...], max_order: int
               ) -> tuple[list[float], list[int], RowSpace] | None:
    """Rank at hover (rates 0, nominal coefficients, constant hover input); None without hover."""
    speeds = hover_input(model)
    if speeds is None:
        return None
    drift = [model.drift[k] + sum((model.rotor_fields[i][k] * speeds[i]
                                   for i in range(model.rotor_count)),
                                  sympy.Poly(0, *model.symbols, domain="QQ"))
             for k in range(3)]
    point = {}
    for name, sym in zip(model.state_names, model.symbols):
        point[sym] = sympy.Integer(1) if name.startswith(("kf", "km")) else sympy.Integer(0)
    level = list(model.gyro) if "gyro" in measurements else []
    if "accel" in measurements:
        level.append(sum((term * speeds[i] for i, term in enumerate(model.accel_terms)),
                         sympy.Poly(0, *model.symbols, domain="QQ")))
    seen: set = set()
    level = _dedupe(level, seen)
    space = RowSpace(model.n)
    ranks = []
    for order in range(max_order + 1):
        for function in level:
            space.add(_gradient_at(model, function, point))
        ranks.append(space.rank)
        if space.rank == model.n or (order > 0 and ranks[-1] == ranks[-2]) or order == max_order:
            break
        level = _dedupe([lie_derivative(model, function, drift) for function in level], seen)
    return [float(s) for s in speeds], ranks, space


def describe_direction(names: list[str], vector: list[Fraction]) -> str:
    """'kf_1 - kf_3' style text of a state-space direction (integer coefficients when exact). A weight below
    NEGLIGIBLE_WEIGHT of the largest is the rounding of the geometry's floats (a plus frame's cos 90 deg arm
    written as 2.6e-18 m), not a direction: left out."""
    largest_weight = max((abs(value) for value in vector), default=Fraction(0))
    nonzero = [(names[j], value) for j, value in enumerate(vector)
               if value != 0 and abs(value) > NEGLIGIBLE_WEIGHT * largest_weight]
    if not nonzero:
        return "0"
    if nonzero[0][1] < 0:  # a direction and its opposite are the same statement
        nonzero = [(name, -value) for name, value in nonzero]
    denominators = 1
    for _, value in nonzero:
        denominators = denominators * value.denominator // _gcd(denominators, value.denominator)
    scaled = [(name, value * denominators) for name, value in nonzero]
    common = 0
    for _, value in scaled:
        common = _gcd(common, abs(value.numerator))
    scaled = [(name, value / common) for name, value in scaled]
    small_integers = all(abs(value) <= 100 for _, value in scaled)
    largest = max(abs(value) for _, value in scaled)
    parts = []
    for name, value in scaled:
        if small_integers:
            text = "" if abs(value) == 1 else f"{abs(value)} "
        else:  # irrational geometry (cos 45 deg) read as decimals: relative weights
            ratio = f"{float(abs(value) / largest):.3g}"
            text = "" if ratio == "1" else f"{ratio} "
        sign = "-" if value < 0 else "+"
        parts.append(f"{sign} {text}{name}")
    out = " ".join(parts)
    return out[2:] if out.startswith("+ ") else "-" + out[2:]


def _gcd(a: int, b: int) -> int:
    while b:
        a, b = b, a % b
    return abs(a)


def analyse(vehicle: Vehicle, measurements: tuple[str, ...], max_order: int = MAX_ORDER_DEFAULT,
            progress=None) -> Result:
    bad = [m for m in measurements if m not in MEASUREMENTS]
    if bad or not measurements:
        raise UserError(f"--measure: expected gyro or gyro,accel, got {','.join(measurements)!r}")
    if max_order < 1:
        raise UserError("--max-order must be at least 1")
    model = build_model(vehicle)
    ranks, counts = generic_rank(model, measurements, max_order, progress=progress)
    hover = hover_rank(model, measurements, max_order)
    speeds, hover_ranks, space = hover if hover else ([], [], None)
    return Result(
        vehicle=vehicle.name or (str(vehicle.path) if vehicle.path else "vehicle"),
        measurements=tuple(measurements),
        state_names=model.state_names,
        generic_rank=ranks[-1],
        rank_by_order=ranks,
        functions_by_order=counts,
        hover_input=speeds,
        hover_rank=hover_ranks[-1] if space else None,
        hover_rank_by_order=hover_ranks,
        hover_null_space=space.null_space() if space else [],
        hover_row_space=[space.pivots[col] for col in sorted(space.pivots)] if space else [],
    )


def render_text(result: Result) -> str:
    lines = [
        f"vehicle {result.vehicle}: {result.n} states "
        f"({(result.n - 6) // 2} rotors), measurements {'+'.join(result.measurements)}",
        f"generic rank (every rotor speed a free input): {result.generic_rank} of {result.n} -> "
        + ("locally weakly observable" if result.observable else "NOT observable"),
        "  rank after Lie-derivative order 0..k: "
        + ", ".join(str(r) for r in result.rank_by_order)
        + "  (distinct functions per order: " + ", ".join(str(c) for c in result.functions_by_order) + ")",
        "no torque-free hover with positive rotor speeds: hover not analysed"
        if result.hover_rank is None else
        f"at hover (rates 0, constant torque-free speeds^2 "
        f"{', '.join(f'{s:.3g}' for s in result.hover_input)} x mean): "
        f"rank {result.hover_rank} of {result.n}",
    ]
    if result.hover_rank is None:
        return "\n".join(lines) + "\n"
    lines.append("  combinations seen at hover (reduced basis):")
    lines += [f"    {text}" for text in result.hover_seen_combinations()]
    if result.hover_null_space:
        lines.append("  unobservable directions at hover (perturbations the measurements cannot see):")
        lines += [f"    {describe_direction(result.state_names, v)}" for v in result.hover_null_space]
    observable = result.hover_observable_states()
    lines.append("  states observable on their own at hover: " + (", ".join(observable) or "none"))
    return "\n".join(lines) + "\n"
