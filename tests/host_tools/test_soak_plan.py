"""The soak's flight plan declares the inertia uncertainty by one rule for every flight."""

from __future__ import annotations

import math
import random


def declared_inertia_std(cmd: list[str]) -> float:
    return float(cmd[cmd.index("--filter-inertia-std") + 1])


def test_every_flight_declares_the_same_inertia_std(soak_script):
    soak = soak_script("soak")
    rng = random.Random(1)
    cases = [soak.plan_case(rng, i) for i in range(400)]
    with_error = [c for c in cases if any(e.startswith("inertia_error=") for e in c["effects"])]
    without = [c for c in cases if c not in with_error]
    assert with_error and without
    values = {declared_inertia_std(soak.command("sitl", c, mode, "x.json"))
              for c in cases for mode in ("filter", "oracle")}
    assert len(values) == 1  # nothing tells the filter which flight carries the error
    assert math.isclose(values.pop(), soak.plan_inertia_rel_rms(), rel_tol=1e-5)
    assert declared_inertia_std(soak.command("sitl", with_error[0], "filter", "x.json", inertia_std=0.0)) == 0.0


def test_declared_inertia_std_is_the_plans_rms_error(soak_script):
    """The closed form against the plan itself: the RMS of the drawn
    inertia_error strength over many cases (0 where the effect is absent)."""
    soak = soak_script("soak")
    rng = random.Random(7)
    total, count = 0.0, 40000
    for i in range(count):
        for effect in soak.plan_case(rng, i)["effects"]:
            if effect.startswith("inertia_error="):
                total += float(effect.split("=", 1)[1]) ** 2
    measured = math.sqrt(total / count)
    assert abs(measured - soak.plan_inertia_rel_rms()) < 0.03 * soak.plan_inertia_rel_rms()
