"""Effect magnitudes for the bench: plausible physical ranges and the detection limit.

Every effect of propid_sitl (`--effect NAME=STRENGTH`, docs/sitl.md) gets a
plausible range of its strength parameter, from the physics of real vehicles
(docs/gap-bench.md gives the reasoning per row). Inside that range, the bench
picks each flight's strength by how detectable it makes the effect (the oracle
detectability index of propid.gapbench.detectability): a target index is drawn
log-uniformly between the detection limit and DETECTABILITY_MAX, and the strength
that gives it on this very flight (measured with a probe flight at PROBE strength,
then scaled linearly) is used, clipped to the plausible range. An effect that
cannot reach the limit at its plausible maximum on a flight stays at that maximum
and is scored separately as "below the detection limit".
"""

from __future__ import annotations

from dataclasses import dataclass

# The oracle detectability index at which an effect counts as detectable: a
# 5-sigma matched-filter detection by someone who knows the effect's exact
# signature (a real tool, which must also find the signature, needs more).
DETECTION_LIMIT = 5.0
# Upper end of the drawn detectability: 10x the limit (clear, not overwhelming).
DETECTABILITY_MAX = 50.0


@dataclass(frozen=True)
class EffectRange:
    effect: str
    probe: float        # strength of the probe flight (the SITL's default strength)
    strength_max: float  # largest plausible |strength|
    signed: bool         # the strength may be negative (drawn with a random sign)
    unit: str


EFFECT_RANGES: dict[str, EffectRange] = {r.effect: r for r in (
    # Multipliers of the SITL's physical constants (docs/sitl.md): the constants are
    # catalogue or scaled values, real propellers, motor bells and guards differ by
    # a factor of a few.
    EffectRange("rotor_inertia", 1.0, 3.0, False, "x J_rotor"),
    EffectRange("rotor_gyroscopic", 1.0, 3.0, False, "x J_rotor"),
    EffectRange("rotor_drag", 1.0, 3.0, False, "x (k_d, k_z, k_flap)"),
    EffectRange("translational_lift", 1.0, 3.0, False, "x k_h"),
    EffectRange("aero_damping", 1.0, 3.0, False, "x (k_d, k_z)"),
    # Measured multirotor ground effect exceeds the single-rotor image model by up
    # to about 2x (rotor interaction under the body).
    EffectRange("ground_effect", 1.0, 2.0, False, "x Cheeseman-Bennett gain"),
    # A battery or camera strapped off-centre: up to 20 % of the arm.
    EffectRange("com_offset", 0.05, 0.2, True, "fraction of the arm"),
    # CAD inertia without wiring and battery placement: off by up to 40 %.
    EffectRange("inertia_error", 0.1, 0.4, True, "relative"),
    # Serial (UART) telemetry polled round-robin: up to ~50 ms behind.
    EffectRange("esc_delay", 0.02, 0.05, False, "s"),
    # Static-thrust exponents of small propellers 1.7-2.3.
    EffectRange("thrust_nonlinearity", 0.1, 0.3, True, "extra exponent"),
    # MEMS sensitivity tolerance plus mounting misalignment: up to 5 %.
    EffectRange("gyro_scale", 0.02, 0.05, True, "scale error"),
)}

EFFECTS: tuple[str, ...] = tuple(EFFECT_RANGES)


def clip_strength(effect: str, strength: float) -> tuple[float, bool]:
    """Strength limited to the plausible range; True when it had to be clipped."""
    limit = EFFECT_RANGES[effect].strength_max
    if abs(strength) > limit:
        return (limit if strength > 0 else -limit), True
    return strength, False
