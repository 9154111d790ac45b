"""gap-bench: scoring rules on hand-made answer/result pairs, signal helpers, and a
three-flight bench end to end with a stand-in diagnosis that records what it was given.

The end-to-end test needs propid_sitl (the sitl_binary fixture, conftest.py).
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from propid.gapbench.plan import further_flight, make_plan
from propid.gapbench.rigid_body import lowpass
from propid.gapbench.runner import BenchConfig, run_bench
from propid.gapbench.scoring import score_flight, shrink_of, summarize
from propid.gapbench.table import render

def answer(flight_id, kind, effects, below=False, index=12.0):
    return {"flight_id": flight_id, "kind": kind,
            "effects": [{"id": e, "detectability": index, "below_limit": below} for e in effects]}


def result(verdict, significant=(), other=(), ambiguous=None, shrink=None):
    effects = [{"id": e, "explained_fraction": 0.5, "significant": True} for e in significant]
    effects += [{"id": e, "explained_fraction": 0.01, "significant": False} for e in other]
    out = {"verdict": verdict, "effects": effects, "shrink": shrink or {}}
    if ambiguous is not None:
        out["ambiguous"] = ambiguous
    return out


def test_single_effect_right_only_when_the_verdict_is_the_truth():
    a = answer("f0", "single", ["esc_delay"])
    assert score_flight(a, result("esc_delay", ["esc_delay"]))["right"]
    wrong = score_flight(a, result("rotor_inertia", ["rotor_inertia", "esc_delay"]))
    assert not wrong["right"] and wrong["false_effect"] and wrong["false_named"] == ["rotor_inertia"]
    missed = score_flight(a, result("none", [], ["esc_delay"]))
    assert not missed["right"] and not missed["false_effect"]


def test_pair_needs_both_as_the_top_two_significant_in_any_order():
    a = answer("f1", "pair", ["com_offset", "gyro_scale"])
    assert score_flight(a, result("gyro_scale", ["gyro_scale", "com_offset"]))["right"]
    assert not score_flight(a, result("gyro_scale", ["gyro_scale"], ["com_offset"]))["right"]
    third = score_flight(a, result("gyro_scale", ["gyro_scale", "esc_delay", "com_offset"]))
    assert not third["right"] and third["false_effect"]


def test_effect_free_and_failed_runs():
    a = answer("f2", "none", [])
    assert score_flight(a, result("none"))["right"]
    false_alarm = score_flight(a, result("aero_damping", ["aero_damping"]))
    assert not false_alarm["right"] and false_alarm["false_effect"]
    failed = score_flight(a, None)
    assert failed["failed"] and not failed["right"]
    assert score_flight(a, {"effects": []})["failed"]  # no verdict at all


def test_ambiguous_is_wrong_but_counted_apart():
    a = answer("f3", "single", ["inertia_error"])
    r = result("none", [], ambiguous=[{"candidates": ["inertia_error", "gyro_scale"]}])
    scored = score_flight(a, r)
    assert not scored["right"] and scored["ambiguous_hit"]


def test_a_wrong_member_reported_ambiguous_with_the_truth_is_not_a_false_effect():
    """The issue lets look-alikes be reported as ambiguous with the candidates: a significant
    wrong member of a group that holds the true effect is not a false effect (strict rate
    apart), not right either; a group without the truth does not excuse it."""
    a = answer("f4", "single", ["thrust_nonlinearity"])
    group = [{"candidates": ["inertia_error", "thrust_nonlinearity"], "kept": "inertia_error"}]
    scored = score_flight(a, result("inertia_error", ["inertia_error"], ambiguous=group))
    assert not scored["right"] and scored["ambiguous_hit"]
    assert not scored["false_effect"] and scored["false_effect_strict"]
    assert scored["ambiguous_named"] == ["inertia_error"]
    other = score_flight(answer("f5", "single", ["com_offset"]),
                         result("inertia_error", ["inertia_error"], ambiguous=group))
    assert other["false_effect"] and other["false_named"] == ["inertia_error"]
    s = summarize([scored, other])
    assert s["false_effect_rate"] == 0.5 and s["false_effect_rate_strict"] == 1.0


def test_shrink_is_the_best_axis_reduction():
    r = result("x", shrink={"roll": {"rms_before": 2.0, "rms_after": 1.0},
                            "yaw": {"rms_before": 4.0, "rms_after": 1.0},
                            "thrust": {"rms_before": None, "rms_after": 1.0}})
    assert shrink_of(r) == pytest.approx(0.75)
    assert shrink_of({"verdict": "none"}) is None


def test_prediction_error_shrink_and_the_library_bound_are_scored_beside_the_rms():
    r = result("com_offset", ["com_offset"], shrink={
        "roll": {"rms_before": 2.0, "rms_after": 1.8, "rms_library_in_sample": 1.5,
                 "pred_0.1s_before": 1.0, "pred_0.1s_after": 0.4, "pred_0.5s_before": 1.0, "pred_0.5s_after": 0.2},
        "yaw": {"rms_before": 4.0, "rms_after": 3.8, "rms_library_in_sample": 3.0,
                "pred_0.1s_before": 2.0, "pred_0.1s_after": 1.5, "pred_0.5s_before": 2.0, "pred_0.5s_after": 1.9}})
    rec = score_flight(answer("a", "single", ["com_offset"]), r)
    assert rec["shrink"] == pytest.approx(0.1)
    assert rec["shrink_pred_0.1s"] == pytest.approx(0.6) and rec["shrink_pred_0.5s"] == pytest.approx(0.8)
    assert rec["shrink_library_bound"] == pytest.approx(0.25)
    missed = score_flight(answer("b", "single", ["com_offset"]), result("none", shrink={
        "roll": {"rms_before": 2.0, "rms_after": 2.0, "rms_library_in_sample": 1.0}}))
    assert missed["shrink_pred_0.1s"] is None and missed["shrink_library_bound"] == pytest.approx(0.5)
    s = summarize([rec, missed])
    # medians over the flights named right; the bound also over every effect flight
    assert s["shrink_pred_0.5s_median"] == pytest.approx(0.8)
    assert s["shrink_library_bound_median"] == pytest.approx(0.25)
    assert s["shrink_library_bound_median_all"] == pytest.approx(0.375)


def test_summary_counts_and_keeps_sub_limit_flights_out_of_the_headline():
    records = [
        score_flight(answer("a", "single", ["esc_delay"]), result("esc_delay", ["esc_delay"])),
        score_flight(answer("b", "single", ["esc_delay"]), result("none")),
        score_flight(answer("c", "pair", ["esc_delay", "com_offset"]),
                     result("com_offset", ["com_offset", "esc_delay"])),
        score_flight(answer("d", "none", []), result("gyro_scale", ["gyro_scale"])),
        score_flight(answer("e", "single", ["ground_effect"], below=True, index=2.0), result("none")),
    ]
    s = summarize(records)
    assert s["flights"] == 5 and s["headline_flights"] == 4
    esc = dict(s["per_effect"]["esc_delay"])
    bands = esc.pop("by_detectability")
    assert esc == {"n": 2, "right": 1, "accuracy": 0.5, "false_named_elsewhere": 0}
    assert bands["10-20"] == {"n": 2, "right": 1} and bands["5-10"] == {"n": 0, "right": 0}
    # the power curve counts below-limit flights too, in their own band
    assert s["per_effect"]["ground_effect"]["by_detectability"]["0-5"] == {"n": 1, "right": 0}
    assert s["per_effect"]["ground_effect"]["n"] == 0
    assert s["per_effect"]["gyro_scale"]["false_named_elsewhere"] == 1
    assert s["singles"]["accuracy"] == 0.5
    assert s["pairs"]["accuracy"] == 1.0
    assert s["none"]["accuracy"] == 0.0
    assert s["overall"]["accuracy"] == pytest.approx(2 / 4)
    assert s["false_effect_rate"] == pytest.approx(1 / 4)
    assert s["below_limit"] == {"n": 1, "accuracy": 0.0}
    assert s["by_detectability"]["0-5"]["n"] == 1


def test_truths_under_the_tools_reporting_floors_are_counted_beside_the_headline():
    """An esc_delay under 5 ms or a scale error under 3 % is below what the tool reports by its
    own documented floors: such flights stay in the headline, and are counted apart beside it."""
    def drawn(fid, kind, effects):
        return {"flight_id": fid, "kind": kind, "effects": [
            {"id": e, "strength": v, "detectability": 12.0, "below_limit": False} for e, v in effects]}
    records = [
        score_flight(drawn("a", "single", [("esc_delay", 0.001)]), result("none")),
        score_flight(drawn("b", "single", [("esc_delay", 0.02)]), result("esc_delay", ["esc_delay"])),
        score_flight(drawn("c", "single", [("gyro_scale", -0.02)]), result("none")),
        score_flight(drawn("d", "single", [("inertia_error", 0.1)]), result("none")),
        score_flight(drawn("e", "pair", [("gyro_scale", 0.007), ("com_offset", 0.1)]),
                     result("com_offset", ["com_offset"])),
        score_flight(drawn("f", "single", [("thrust_nonlinearity", 0.01)]), result("none")),
    ]
    assert [r["under_floor"] for r in records] == [True, False, True, False, True, False]
    s = summarize(records)
    assert s["overall"] == {"n": 6, "accuracy": pytest.approx(1 / 6)}  # the headline is unchanged
    assert s["under_floor"] == {"n": 3, "accuracy": 0.0}
    assert s["above_floors"]["overall"] == {"n": 3, "accuracy": pytest.approx(1 / 3)}
    assert s["above_floors"]["singles"]["n"] == 3 and s["above_floors"]["pairs"]["n"] == 0
    assert "truth under the tool's reporting floors" in render({"tool": s, "baseline": s})


def test_k_flights_per_diagnosis_keep_the_one_flight_plan_and_draw_further_flights():
    one = make_plan(seed=5, singles_per_effect=2, pairs=4, nones=3)
    three = make_plan(seed=5, singles_per_effect=2, pairs=4, nones=3, flights_per_diagnosis=3)
    assert len(one) == len(three)
    for a, b in zip(one, three):
        assert a.extra == {} and b.extra["flights_per_diagnosis"] == 3
        b_dict = b.to_dict()
        b_dict["extra"] = {}
        assert a.to_dict() == b_dict  # the first flights are the one-flight plan's
    for spec in three:
        seeds = set()
        for number in (2, 3):
            seed, trajectory = further_flight(spec, number)
            assert (seed, trajectory) == further_flight(spec, number)  # reproducible
            assert further_flight(spec, number, attempt=1)[0] != seed  # a retry redraws
            seeds.add(seed)
            low = trajectory.start_height < 0.6  # rotor radii above ground, not 0.6-1.5 m
            assert low == bool(spec.extra["low"])
            if "ground_effect" in spec.effects:
                assert low
        assert len(seeds | {spec.seed}) == 3  # each flight its own noise
    with pytest.raises(ValueError):
        further_flight(three[0], 4)
    with pytest.raises(ValueError):
        further_flight(one[0], 2)
    with pytest.raises(ValueError):
        make_plan(seed=5, flights_per_diagnosis=0)


def test_a_k_flight_diagnosis_is_scored_as_one_and_banded_by_its_pooled_detectability():
    a = answer("f0", "pair", ["esc_delay", "com_offset"], index=7.0)
    a["effects"][0]["pooled_detectability"] = 14.0
    a["effects"][1]["pooled_detectability"] = 25.0
    right = score_flight(a, result("esc_delay", significant=["esc_delay", "com_offset"]))
    assert right["right"] and right["detectability"] == 7.0
    assert right["pooled_detectability"] == 14.0  # the weaker effect's, like D
    b = answer("f1", "single", ["esc_delay"], index=30.0)
    b["effects"][0]["pooled_detectability"] = 45.0
    wrong = score_flight(b, result("none"))
    s = summarize([right, wrong])
    assert s["by_detectability"]["5-10"] == {"n": 1, "accuracy": 1.0}
    assert s["by_pooled_detectability"]["10-20"] == {"n": 1, "accuracy": 1.0}
    assert s["by_pooled_detectability"]["20-inf"] == {"n": 1, "accuracy": 0.0}
    assert s["by_pooled_detectability"]["5-10"]["n"] == 0
    assert "pooled D over the flights 10-20" in render({"tool": s, "baseline": s})
    # one flight per diagnosis: no pooled figures at all
    single = summarize([score_flight(answer("f2", "single", ["esc_delay"]), result("esc_delay"))])
    assert "by_pooled_detectability" not in single
    assert "pooled D" not in render({"tool": single, "baseline": single})


def test_lowpass_keeps_a_slow_sine_and_differentiates_it():
    fs = 500.0
    t = np.arange(0, 6, 1 / fs)
    slow = np.sin(2 * np.pi * 1.0 * t) + 0.3 * t
    fast = 0.5 * np.sin(2 * np.pi * 60.0 * t)
    filtered, derivative = lowpass(slow + fast, fs, 10.0)
    inner = slice(250, -250)
    assert np.max(np.abs(filtered[inner] - slow[inner])) < 0.02
    expected = 2 * np.pi * np.cos(2 * np.pi * t) + 0.3
    assert np.max(np.abs(derivative[inner] - expected[inner])) < 0.1


FAKE_TOOL = """
import argparse, json, sys
p = argparse.ArgumentParser()
p.add_argument("--log", action="append"); p.add_argument("--vehicle"); p.add_argument("--json")
p.add_argument("--report")
a = p.parse_args()
headers = [open(log).readline().strip().split(",") for log in a.log]
vehicle = json.load(open(a.vehicle))
json.dump({"verdict": "none", "effects": [], "shrink": {}, "seen_columns": headers[0],
           "seen_logs": a.log, "seen_columns_per_log": headers,
           "seen_notes": vehicle.get("notes")}, open(a.json, "w"))
"""


def test_three_flights_end_to_end_blind_and_scored(tmp_path, sitl_binary):
    tool = tmp_path / "fake_gap.py"
    tool.write_text(FAKE_TOOL)
    config = BenchConfig(out_dir=tmp_path / "bench", result_path=tmp_path / "gap_bench.json",
                         sitl=sitl_binary, seed=3, singles_per_effect=1, pairs=0, nones=1,
                         effects=("esc_delay", "com_offset"), duration_s=6.0, workers=2,
                         tool_command=[sys.executable, str(tool)])
    out = run_bench(config, progress=False)
    saved = json.loads(config.result_path.read_text())
    assert saved["tool_available"] and not saved["errors"]
    assert len(saved["flights"]) == 3
    kinds = sorted(f["kind"] for f in saved["flights"])
    assert kinds == ["none", "single", "single"]
    for key in ("tool", "baseline"):
        summary = saved[key]
        for part in ("overall", "singles", "pairs", "none", "per_effect", "by_detectability"):
            assert part in summary
        assert summary["flights"] == 3
    # The stand-in always says "none": right on the effect-free flight, wrong on the others.
    assert saved["tool"]["none"]["accuracy"] == 1.0
    assert saved["tool"]["singles"]["accuracy"] in (0.0, None)
    # Blind: the tool saw measured columns only, and no notes naming the effects.
    for flight in saved["flights"]:
        seen = json.loads((config.out_dir / "tool" / f"{flight['flight_id']}.json").read_text())
        assert "gyro_x" in seen["seen_columns"] and "omega_4" in seen["seen_columns"]
        assert not [c for c in seen["seen_columns"]
                    if c.startswith(("true_", "est_", "std_", "ref_")) or c in ("health", "status")]
        assert seen["seen_notes"] == ""
    # The answer key has the truth the tool never saw.
    for flight in saved["flights"]:
        key = json.loads((config.out_dir / "answers" / f"{flight['flight_id']}.json").read_text())
        for effect in key["effects"]:
            assert effect["strength"] != 0 and effect["detectability"] > 0
    assert "least squares" in render(out)
    assert "single effects right / flown, by D" in render(out)
    # the census: the stand-in names nothing and reports no entry, so each headline single's truth
    # is missed as untestable (or under a reporting floor, checked first)
    missed = [f for f in saved["flights"] if f["kind"] == "single" and f["tool"]["headline"]]
    assert sum(saved["census"]["misses"].values()) == len(missed)
    assert set(saved["census"]["misses"]) <= {"untestable", "under a reporting floor"}
    assert saved["census"]["false"] == {}
    assert all("census" in f["tool"] for f in saved["flights"])
    assert "why true effects were missed" in render(out)


def test_two_flights_per_diagnosis_end_to_end(tmp_path, sitl_binary):
    # plan seed 5: both flights of the effect's diagnosis fly (with seed 3 the second one, a circle
    # started 6 cm up, crashes and has no free flight: D = 0, test_gap_bench_detectability.py)
    tool = tmp_path / "fake_gap.py"
    tool.write_text(FAKE_TOOL)
    config = BenchConfig(out_dir=tmp_path / "bench", result_path=tmp_path / "gap_bench.json",
                         sitl=sitl_binary, seed=5, singles_per_effect=1, pairs=0, nones=1,
                         effects=("com_offset",), duration_s=6.0, workers=2,
                         tool_command=[sys.executable, str(tool)], flights_per_diagnosis=2)
    out = run_bench(config, progress=False)
    assert not out["errors"] and out["config"]["flights_per_diagnosis"] == 2
    assert sorted(f["kind"] for f in out["flights"]) == ["none", "single"]
    for flight in out["flights"]:
        fid = flight["flight_id"]
        key = json.loads((config.out_dir / "answers" / f"{fid}.json").read_text())
        (further,) = key["further_flights"]
        # the second flight: the first one's vehicle, its own noise seed, the same effects
        assert further["vehicle_seed"] == key["seed_flown"] != further["seed_flown"]
        assert f"--vehicle-seed {key['seed_flown']} " in further["sitl_command"]
        assert f"--seed {further['seed_flown']} " in further["sitl_command"]
        for effect in key["effects"]:
            assert f"--effect {effect['id']}=" in further["sitl_command"]
            first, second = effect["detectability_per_flight"]
            assert first == effect["detectability"] and second > 0
            # one shared kf/km for both flights: at least the two flights' D added in quadrature
            assert effect["pooled_detectability"] >= 0.999 * np.hypot(first, second)
        # the tool got both blind logs, measured columns only
        seen = json.loads((config.out_dir / "tool" / f"{fid}.json").read_text())
        assert [p.rsplit("/", 1)[-1] for p in seen["seen_logs"]] == [f"{fid}.csv", further["csv"]]
        for columns in seen["seen_columns_per_log"]:
            assert "gyro_x" in columns and not [c for c in columns if c.startswith("true_")]
    single = next(f for f in out["flights"] if f["kind"] == "single")
    assert single["tool"]["pooled_detectability"] > single["tool"]["detectability"]
    assert "by_pooled_detectability" in out["tool"]
    assert "2 flights per diagnosis" in render(out)
