"""gap-bench census: the rule that decided each missed true effect and the kind of each false
effect, read from hand-made OUT.json entries (docs/gap-bench.md, "Where the accuracy is lost")."""

from __future__ import annotations

from propid.gapbench.census import flight_census, miss_cause, render_census, summarize_census
from propid.gapbench.scoring import score_flight

CANDIDATES = ["rotor_inertia", "rotor_gyroscopic", "inertia_error", "gyro_scale", "thrust_nonlinearity",
              "com_offset", "aero_damping", "rotor_drag", "translational_lift", "ground_effect"]  # K = 10


def entry(eid, significant=False, p=1e-9, held=1e-9, **extra):
    return {"id": eid, "significant": significant, "explained_fraction": 0.1, "p_value": p,
            "held_out_p_value": held, "physical_sign": True, "effect_size": 0.1, **extra}


def result(named=(), changes=None, ambiguous=(), delay=None):
    changes = changes or {}
    effects = [entry(e, significant=True) for e in named]
    effects += [changes.get(e, entry(e)) for e in CANDIDATES if e not in named]
    lag = {"id": "esc_delay", "significant": "esc_delay" in named, "explained_fraction": 0.05,
           "ci": [0.01, 0.09], "params": {"delay_s": 0.0 if delay is None else delay}}
    effects.insert(0 if "esc_delay" in named else len(effects), lag)
    effects.sort(key=lambda e: not e["significant"])
    verdict = next((e["id"] for e in effects if e["significant"]), "none")
    return {"verdict": verdict, "effects": effects, "ambiguous": list(ambiguous), "untestable": [],
            "inputs": {"rate_hz": [500.0]}}


def truth(eid, strength=1.0):
    return {"id": eid, "strength": strength, "detectability": 15.0}


def cause(eid, res, strength=1.0):
    return miss_cause(truth(eid, strength), res, [])


def test_each_admissibility_rule_is_named_as_the_cause():
    assert cause("rotor_drag", result(changes={"rotor_drag": entry("rotor_drag", physical_sign=False)})) == "physical sign"
    assert cause("ground_effect", result(changes={"ground_effect": entry(
        "ground_effect", implausible="implausible: ground_gain = 2.6")})) == "plausibility range"
    assert cause("thrust_nonlinearity", result(changes={"thrust_nonlinearity": entry(
        "thrust_nonlinearity", effect_size=0.02)})) == "scale floor"
    assert cause("com_offset", result(changes={"com_offset": entry("com_offset", dropped={"reason": "x"})})) \
        == "dropped by the backward check"


def test_the_tests_are_read_against_the_first_holm_bar():
    # K = 10 candidates: the first bar is 0.005 for both tests
    assert cause("com_offset", result(changes={"com_offset": entry("com_offset", p=0.006)})) == "Wald test"
    assert cause("com_offset", result(changes={"com_offset": entry("com_offset", p=0.004, held=0.02)})) \
        == "held-out replication"
    assert cause("com_offset", result(changes={"com_offset": entry("com_offset", p=0.004, held=0.004)})) \
        == "Holm order"
    on_lag = entry("aero_damping", p=1e-6, held=1e-6,
                   conditioned_on={"on": "residual_lag", "p_value": 1e-6, "held_out_p_value": 0.2, "physical_sign": True})
    assert cause("aero_damping", result(changes={"aero_damping": on_lag})) == "on top of the residual lag"


def test_floors_ranking_and_ambiguity_come_before_the_tests():
    assert cause("gyro_scale", result(changes={"gyro_scale": entry("gyro_scale", p=0.5)}), strength=0.01) \
        == "under a reporting floor"
    assert cause("gyro_scale", result(named=["inertia_error", "gyro_scale"])) == "named, ranked below a look-alike"
    assert cause("com_offset", result(named=["rotor_drag", "com_offset"])) == "named, ranked below another effect"
    amb = [{"candidates": ["inertia_error", "gyro_scale"], "kept": "inertia_error"}]
    assert cause("gyro_scale", result(named=["inertia_error"], ambiguous=amb)) == "ambiguous with a look-alike"


def test_a_lag_is_judged_by_its_own_floors_and_evidence():
    assert cause("esc_delay", result(delay=0.003), strength=0.02) == "lag fitted under the reporting floors"
    shown_small = result(delay=0.02)
    next(e for e in shown_small["effects"] if e["id"] == "esc_delay")["explained_fraction"] = 0.01
    assert cause("esc_delay", shown_small, strength=0.02) == "lag shown, share under the 2 % floor"
    hidden = result(delay=0.02)
    next(e for e in hidden["effects"] if e["id"] == "esc_delay")["ci"] = [-0.05, 0.1]
    assert cause("esc_delay", hidden, strength=0.02) == "lag not shown"


def test_flight_census_counts_headline_misses_and_false_effects_by_kind():
    pair = {"flight_id": "f1", "kind": "pair", "effects": [truth("rotor_drag"), truth("ground_effect")]}
    res = result(named=["thrust_nonlinearity", "rotor_drag"],
                 changes={"ground_effect": entry("ground_effect", held=0.19)})
    rec = score_flight(pair, res)
    census = flight_census(pair, res, rec)
    assert census["misses"] == [{"effect": "ground_effect", "cause": "held-out replication"}]
    assert census["false"] == [{"effect": "thrust_nonlinearity", "kind": "look-alike of a true effect"}]
    none = {"flight_id": "f2", "kind": "none", "effects": []}
    res_none = result(named=["rotor_drag"])
    rec_none = score_flight(none, res_none)
    assert flight_census(none, res_none, rec_none) == {
        "misses": [], "false": [{"effect": "rotor_drag", "kind": "on an effect-free flight"}]}
    single = {"flight_id": "f3", "kind": "single", "effects": [truth("com_offset")]}
    failed = flight_census(single, None, score_flight(single, None))
    assert failed["misses"] == [{"effect": None, "cause": "run failed"}]
    right = result(named=["com_offset"])
    assert flight_census(single, right, score_flight(single, right)) == {"misses": [], "false": []}
    below = {"flight_id": "f4", "kind": "single", "effects": [dict(truth("com_offset"), below_limit=True)]}
    res_below = result()
    records = [rec, rec_none, score_flight(below, res_below)]
    summary = summarize_census([census, flight_census(none, res_none, rec_none),
                                flight_census(below, res_below, records[2])], records)
    assert summary == {"misses": {"held-out replication": 1},
                       "false": {"look-alike of a true effect": 1, "on an effect-free flight": 1}}
    text = render_census(summary)
    assert "held-out replication" in text and "on an effect-free flight" in text
