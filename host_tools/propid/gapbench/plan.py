"""The bench's flight plan: which flights, with which effects, vehicles, trajectories, rates.

Everything random is drawn from one numpy generator seeded by the bench seed, so
a plan is reproducible. Effects' strengths are not fixed here: the plan holds a
target detectability per effect, the flight maker turns it into a strength
(propid.gapbench.magnitudes).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from propid.gapbench.magnitudes import DETECTABILITY_MAX, DETECTION_LIMIT, EFFECTS

VEHICLES = ("crazyflie-plus", "crazyflie-x", "hummingbird-plus", "hummingbird-x")

# Log / rotor-telemetry rates [Hz]: the SITL logs one row per control step (500 Hz)
# or fewer (--log-rate); the ESC reports at --esc-rate and the log holds the latest
# report, so a rate below the log rate is a sample-and-hold. Reports carry no
# latency and fall on log instants (--esc-latency 0 --esc-phase 0, set by the flight
# maker): at a report instant the logged rotor speed is the physical one, so any
# lag beyond the hold itself is the esc_delay effect and nothing else.
RATES = (
    {"log_rate": 500, "esc_rate": 500},
    {"log_rate": 500, "esc_rate": 100},
    {"log_rate": 100, "esc_rate": 100},
)


# The SITL's default noise densities (BMI088 typ., docs/sitl.md).
GYRO_NOISE_DENSITY = math.radians(0.014)  # rad/s/sqrt(Hz)
ACCEL_NOISE_DENSITY = 175e-6 * 9.80665     # m/s^2/sqrt(Hz)


@dataclass
class Nuisances:
    """Effect-free disturbances of the measurement (none is an unmodelled effect)."""
    gyro_bias_walk: float | None = None  # rad/s/sqrt(s) (SITL default 1e-4)
    noise_factor: float = 1.0            # x gyro and accelerometer noise density
    esc_dropout: float | None = None     # fraction of ESC reports lost (default 0.01)

    def sitl_args(self) -> list[str]:
        args: list[str] = []
        if self.gyro_bias_walk is not None:
            args += ["--gyro-bias-walk", f"{self.gyro_bias_walk:.6g}"]
        if self.noise_factor != 1.0:
            args += ["--gyro-noise", f"{GYRO_NOISE_DENSITY * self.noise_factor:.6g}",
                     "--accel-noise", f"{ACCEL_NOISE_DENSITY * self.noise_factor:.6g}"]
        if self.esc_dropout is not None:
            args += ["--esc-dropout", f"{self.esc_dropout:.6g}"]
        return args


@dataclass
class Trajectory:
    name: str
    period_s: float
    yaw_amplitude: float
    yaw_cycles: float
    start_height: float

    def sitl_args(self) -> list[str]:
        return ["--trajectory", self.name, "--trajectory-period", f"{self.period_s:.4g}",
                "--yaw-amplitude", f"{self.yaw_amplitude:.4g}", "--yaw-cycles",
                f"{self.yaw_cycles:.4g}", "--start-height", f"{self.start_height:.4g}"]


@dataclass
class FlightSpec:
    flight_id: str
    kind: str                      # "single", "pair" or "none"
    effects: list[str]             # true effect ids (empty for "none")
    signs: list[int]               # sign of each effect's strength (+1 / -1)
    target_detectability: list[float]
    vehicle: str
    trajectory: Trajectory
    rates: dict
    nuisances: Nuisances
    duration_s: float
    seed: int
    extra: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


# Rotor radius of the presets [m] (docs/sitl.md): "low" is 2.5-6 radii above ground,
# where the image-method gain is 0.3-2.6 % of thrust.
ROTOR_RADIUS = {"crazyflie": 0.0231, "hummingbird": 0.10}


def _trajectory(rng: np.random.Generator, low: bool, vehicle: str) -> Trajectory:
    # Circles fly at 0.5-1.3 m/s; Lissajous periods below ~8 s are too aggressive for
    # the nominal-coefficient controller on the small vehicle (measured: it tips over).
    if rng.random() < 0.5:
        name, period = "circle", float(rng.uniform(4.0, 10.0))
    else:
        name, period = "lissajous", float(rng.uniform(8.0, 14.0))
    # Near the ground (rotor radius 0.023-0.1 m) ground effect is a few percent of
    # thrust; every kind of flight flies low sometimes, so altitude alone tells nothing.
    radius = ROTOR_RADIUS[vehicle.split("-")[0]]
    height = float(rng.uniform(2.5, 6.0)) * radius if low else float(rng.uniform(0.6, 1.5))
    return Trajectory(name, period, float(rng.uniform(0.3, 1.5)), float(rng.uniform(0.5, 2.5)),
                      height)


def _nuisances(rng: np.random.Generator, strong: bool) -> Nuisances:
    if not strong:
        return Nuisances()
    return Nuisances(
        gyro_bias_walk=float(10 ** rng.uniform(-3.5, -2.5)),   # 3-30x the default walk
        noise_factor=float(rng.choice([1.0, 2.0, 3.0])),
        esc_dropout=float(rng.choice([0.01, 0.03, 0.05])),
    )


def _target(rng: np.random.Generator) -> float:
    return float(math.exp(rng.uniform(math.log(DETECTION_LIMIT), math.log(DETECTABILITY_MAX))))


def make_plan(seed: int = 1, singles_per_effect: int = 5, pairs: int = 15, nones: int = 15,
              duration_s: float = 12.0, effects: tuple[str, ...] | None = None,
              flights_per_diagnosis: int = 1) -> list[FlightSpec]:
    """The bench's diagnoses: every effect alone, pairs of distinct effects, effect-free.

    Each spec is the diagnosis's first flight. With flights_per_diagnosis K > 1 the spec's
    `extra` says so and keeps whether the flights fly low; the K - 1 further flights of the
    same vehicle are drawn by `further_flight`, from their own generators, so the plan's
    draws (and every first flight) are those of K = 1.
    """
    if flights_per_diagnosis < 1:
        raise ValueError("flights_per_diagnosis must be at least 1")
    rng = np.random.default_rng(seed)
    pool = tuple(effects) if effects else EFFECTS
    unknown = [e for e in pool if e not in EFFECTS]
    if unknown:
        raise ValueError(f"unknown effect(s): {', '.join(unknown)}")
    if pairs and len(pool) < 2:
        raise ValueError("pairs need at least two effects")
    kinds: list[tuple[str, list[str]]] = []
    for effect in pool:
        kinds += [("single", [effect])] * singles_per_effect
    for _ in range(pairs):
        first, second = rng.choice(len(pool), size=2, replace=False)
        kinds.append(("pair", [pool[int(first)], pool[int(second)]]))
    kinds += [("none", [])] * nones
    plan = []
    for index, (kind, effects) in enumerate(kinds):
        low = "ground_effect" in effects or rng.random() < 0.2
        vehicle = VEHICLES[index % len(VEHICLES)]
        plan.append(FlightSpec(
            flight_id=f"f{index:03d}",
            kind=kind,
            effects=effects,
            signs=[int(rng.choice([-1, 1])) for _ in effects],
            target_detectability=[_target(rng) for _ in effects],
            vehicle=vehicle,
            trajectory=_trajectory(rng, low, vehicle),
            rates=dict(RATES[int(rng.integers(len(RATES)))]),
            nuisances=_nuisances(rng, strong=kind == "none" or rng.random() < 0.3),
            duration_s=duration_s,
            seed=int(rng.integers(1, 2**31 - 1)),
            extra={} if flights_per_diagnosis == 1 else
            {"flights_per_diagnosis": flights_per_diagnosis, "low": low},
        ))
    return plan


def flights_per_diagnosis(spec: FlightSpec) -> int:
    return int(spec.extra.get("flights_per_diagnosis", 1))


def further_flight(spec: FlightSpec, number: int, attempt: int = 0) -> tuple[int, Trajectory]:
    """The noise seed and trajectory of the diagnosis's flight `number` (2..K), another flight
    of the first one's vehicle: the effects, strengths, rates and nuisances stay the first
    flight's; the trajectory is drawn afresh (a flight-test engineer flies several manoeuvres),
    as low as the first one. `attempt` > 0 redraws both after a divergence."""
    if not 2 <= number <= flights_per_diagnosis(spec):
        raise ValueError(f"flight {number} of a {flights_per_diagnosis(spec)}-flight diagnosis")
    rng = np.random.default_rng([spec.seed, number, attempt])
    seed = int(rng.integers(1, 2**31 - 1))
    return seed, _trajectory(rng, bool(spec.extra["low"]), spec.vehicle)
