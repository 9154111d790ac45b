"""The soak's flight plan declares the inertia uncertainty by one rule for every flight; its NEES
figures split the samples outside the band by side."""

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


def clean_flight_summary(inside: int, below: int, above: int) -> dict:
    """A propid_sitl summary of a clean flight with these NEES samples in, below and above the band."""
    return {"exit": 0, "gyro_accepted": 1000, "flown_s": 1.0,
            "honesty": {"nees_in_bounds": inside, "nees_below_bounds": below, "nees_above_bounds": above,
                        "nees_samples": inside + below + above, "nees_dof": 11, "nees_mean": 1.0}}


def test_nees_shares_below_and_above_the_band_per_group_and_flight(soak_script):
    """The NEES samples outside the band are split by side (below: the sigma too large, the safe
    side; above: overconfident), pooled, per group and per flight; the three shares add up."""
    soak = soak_script("soak")
    rng = random.Random(1)
    cases = [case for case in (soak.plan_case(rng, i) for i in range(400)) if case["clean"]]
    default = [case for case in cases if case["sensors"] == "default"][:2]
    paper = [case for case in cases if case["sensors"] == "paper"][:1]
    counts = {default[0]["case"]: (90, 10, 0), default[1]["case"]: (50, 0, 50), paper[0]["case"]: (20, 80, 0)}
    results = {(c, "filter"): clean_flight_summary(*n) for c, n in counts.items()}
    args = type("Args", (), {"jobs": 1, "seed": 1, "inertia_std": None, "steps": 1e7, "nees_tuning": "matched",
                             "gyro_stuck": 0, "nees_rate_rule": "none",
                             "nees_default_rate_noise": None})()
    out = soak.summarise(default + paper, results, 1.0, args)
    assert out["nees_samples"] == 300
    assert (out["nees_in_bounds_pct"], out["nees_below_bounds_pct"], out["nees_above_bounds_pct"]) == \
        (53.33, 30.0, 16.67)  # rounded to 0.01
    group = out["nees_by_group"]["matched tuning, default sensors"]
    assert (group["in_bounds_pct"], group["below_bounds_pct"], group["above_bounds_pct"], group["flights"]) == \
        (70.0, 5.0, 25.0, 2)
    assert out["nees_by_group"]["matched tuning, paper sensors"]["below_bounds_pct"] == 80.0
    sides = {f["case"]: (f["in_bounds_pct"], f["below_bounds_pct"], f["above_bounds_pct"]) for f in out["nees_flights"]}
    assert sides == {c: tuple(float(x) for x in n) for c, n in counts.items()}


def test_pooled_nees_counts_the_flights_outside_the_band_by_side(soak_script):
    """nees_options / rate_noise_rule figures: a flight under 90 % in band is counted
    underconfident when more of its other samples lie below the band than above, else over."""
    rule = soak_script("rate_noise_rule")

    def result(sensors: str, inside: int, below: int, above: int) -> dict:
        return {"case": {"sensors": sensors},
                "r": {"exit": 0, "inside": inside, "below": below, "above": above,
                      "samples": inside + below + above, "cov_repairs": 0, "cov_not_pd": 0, "cov_checks": 0,
                      "false_converged": 0, "converged_claims": 0, "nonfinite": 0}}

    figures = rule.pooled([result("default", 95, 5, 0), result("default", 10, 80, 10),
                           result("default", 50, 10, 40), result("default", 89, 0, 11),
                           result("paper", 0, 100, 0)], "r")
    default = figures["default sensors"]
    assert (default["flights"], default["flights_outside_under"], default["flights_outside_over"]) == (4, 1, 2)
    assert (default["in_band_pct"], default["below_band_pct"], default["above_band_pct"]) == (61.0, 23.75, 15.25)
    assert figures["paper sensors"]["flights_outside_under"] == 1
    assert figures["in_band_pct"] == 48.8
