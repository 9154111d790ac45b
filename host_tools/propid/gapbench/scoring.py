"""Scoring a diagnosis (the tool's or the baseline's OUT.json) against a flight's answer key.

Rules, fixed before any run (docs/gap-bench.md):

- single effect: right when `verdict` is the true effect;
- pair: right when the two highest-ranked significant effects are the two true ones
  (in either order);
- effect-free: right when `verdict` is `none`;
- false effect: a flight on which some significant effect is not a true one
  (reported as the fraction of flights), except a significant effect the tool itself
  reports as ambiguous with a true one (an `ambiguous` entry listing both among its
  candidates): the issue lets look-alikes be "reported as ambiguous with the candidates",
  and such a report names the group, not the wrong member; the strict rate (those counted
  false too) is reported beside it;
- ambiguous: when the tool lists the true effect among `ambiguous` candidates
  instead of naming it, the flight is not right but counted apart;
- flights whose true effect is below the detection limit even at its plausible
  maximum (answer `below_limit`) are scored but kept out of the headline figures;
- under the tool's reporting floors: a flight whose true effect is drawn below a floor
  the tool documents and applies (docs/gap.md: an esc_delay under MIN_REPORTED_LAG_S, the
  sensor chain's own lag; an inertia_error or gyro_scale under MIN_SCALE_EFFECT_SIZE, an
  accelerometer's zero-g offset) stays in the headline figures; the figures without such
  flights and their count are reported beside them (`above_floors`, `under_floor`);
- shrink: per flight, the largest relative reduction of the per-axis residual RMS
  (1 - rms_after / rms_before) over the axes the tool reports; beside it (not the headline)
  the same for the open-loop prediction errors at 0.1 s and 0.5 s and the bound, the most
  the tool's whole library could shrink the RMS (1 - rms_library_in_sample / rms_before).
A run that fails (no OUT.json, bad JSON) is wrong, counted as failed.
"""

from __future__ import annotations

import math

from propid.gap.effects import MIN_REPORTED_LAG_S
from propid.gap.scoring import MIN_SCALE_EFFECT_SIZE
from propid.gapbench.magnitudes import EFFECTS

# Bands of the (smallest true effect's) detectability index, for "at which magnitudes".
DETECTABILITY_BANDS = ((0.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, float("inf")))


# true effects whose strength is a relative torque scale (magnitudes.py units)
SCALE_STRENGTH = ("inertia_error", "gyro_scale")


def under_reporting_floor(effect: dict) -> bool:
    """A true effect drawn below a floor the tool itself applies before naming it."""
    strength = effect.get("strength")
    if not isinstance(strength, (int, float)):
        return False
    if effect["id"] == "esc_delay":
        return abs(strength) < MIN_REPORTED_LAG_S
    if effect["id"] in SCALE_STRENGTH:
        return abs(strength) < MIN_SCALE_EFFECT_SIZE
    return False


def significant_ids(result: dict) -> list[str]:
    """Significant effects in the tool's ranking order."""
    effects = result.get("effects") or []
    return [e.get("id") for e in effects if isinstance(e, dict) and e.get("significant")]


def _ambiguous_groups(result: dict) -> list[set[str]]:
    """The candidate sets of OUT.json's `ambiguous` entries (a bare id is a group of one)."""
    groups: list[set[str]] = []
    entries = result.get("ambiguous") or []
    for entry in entries if isinstance(entries, list) else []:
        if isinstance(entry, str):
            groups.append({entry})
        elif isinstance(entry, dict):
            for key in ("candidates", "ids", "effects"):
                if isinstance(entry.get(key), list):
                    groups.append({str(x) for x in entry[key]})
        elif isinstance(entry, list):
            groups.append({str(x) for x in entry})
    return groups


def _ambiguous_ids(result: dict) -> set[str]:
    return set().union(*_ambiguous_groups(result))


def shrink_of(result: dict, before_key: str = "rms_before", after_key: str = "rms_after") -> float | None:
    """Largest relative reduction over the axes of OUT.json's `shrink`, 1 - after / before
    (default the residual RMS; the prediction errors with their keys, the library's floor
    with "rms_library_in_sample")."""
    shrink = result.get("shrink")
    if not isinstance(shrink, dict):
        return None
    best = None
    for values in shrink.values():
        if not isinstance(values, dict):
            continue
        before, after = values.get(before_key), values.get(after_key)
        if (isinstance(before, (int, float)) and isinstance(after, (int, float))
                and math.isfinite(before) and math.isfinite(after) and before > 0):
            value = 1.0 - after / before
            best = value if best is None else max(best, value)
    return best


# the other shrink figures a record carries: name -> (before key, after key) in OUT.json's shrink
SHRINK_FIGURES = {"shrink_pred_0.1s": ("pred_0.1s_before", "pred_0.1s_after"),
                  "shrink_pred_0.5s": ("pred_0.5s_before", "pred_0.5s_after"),
                  # the most the whole library could shrink the RMS (gap/shrink.py): what bounds shrink
                  "shrink_library_bound": ("rms_before", "rms_library_in_sample")}


def score_flight(answer: dict, result: dict | None) -> dict:
    truth = [e["id"] for e in answer["effects"]]
    kind = answer["kind"]
    below = any(e.get("below_limit") for e in answer["effects"])
    indices = [e["detectability"] for e in answer["effects"]]
    record = {"flight_id": answer["flight_id"], "kind": kind, "truth": truth,
              "below_limit": below, "headline": not below,
              "under_floor": any(under_reporting_floor(e) for e in answer["effects"]),
              "detectability": min(indices) if indices else None}
    pooled = [e["pooled_detectability"] for e in answer["effects"] if "pooled_detectability" in e]
    if pooled:  # a diagnosis of several flights: the oracle's D over all of them too
        record["pooled_detectability"] = min(pooled)
    if not isinstance(result, dict) or "verdict" not in result:
        record.update(failed=True, right=False, false_effect=False, false_effect_strict=False,
                      ambiguous_named=[], verdict=None, named=[],
                      ambiguous_hit=False, shrink=None, **{k: None for k in SHRINK_FIGURES})
        return record
    verdict = result.get("verdict")
    named = significant_ids(result)
    if kind == "single":
        right = verdict == truth[0]
    elif kind == "pair":
        right = len(named) >= 2 and set(named[:2]) == set(truth)
    else:
        right = verdict == "none"
    groups = _ambiguous_groups(result)
    wrong = [e for e in named if e not in truth]
    # a wrong member the tool itself reports as ambiguous with a true effect (see the rules)
    ambiguous_named = [e for e in wrong if any(e in g and g & set(truth) for g in groups)]
    false_named = [e for e in wrong if e not in ambiguous_named]
    ambiguous_hit = (not right) and bool(set(truth) & _ambiguous_ids(result))
    record.update(failed=False, right=bool(right), verdict=verdict, named=named,
                  false_effect=bool(false_named), false_named=false_named,
                  ambiguous_named=ambiguous_named, false_effect_strict=bool(wrong),
                  ambiguous_hit=ambiguous_hit, shrink=shrink_of(result),
                  **{k: shrink_of(result, *keys) for k, keys in SHRINK_FIGURES.items()})
    return record


def _fraction(hits: int, total: int) -> float | None:
    return hits / total if total else None


def _median(values: list[float]) -> float | None:
    values = sorted(v for v in values if v is not None)
    if not values:
        return None
    mid = len(values) // 2
    return values[mid] if len(values) % 2 else 0.5 * (values[mid - 1] + values[mid])


def power_by_band(records: list[dict], key: str = "detectability") -> dict:
    """{band: {"n", "right"}} over DETECTABILITY_BANDS (flights with a measured D; `key`
    "pooled_detectability" for the D over a diagnosis's flights)."""
    out = {}
    for lo, hi in DETECTABILITY_BANDS:
        rows = [r for r in records if r.get(key) is not None and lo <= r[key] < hi]
        out[f"{lo:g}-{hi:g}"] = {"n": len(rows), "right": sum(r["right"] for r in rows)}
    return out


def summarize(records: list[dict]) -> dict:
    """Headline figures over the flights above the detection limit, plus per effect."""
    head = [r for r in records if r["headline"]]
    per_effect = {}
    for effect in EFFECTS:
        rows = [r for r in head if r["kind"] == "single" and r["truth"] == [effect]]
        alone = [r for r in records if r["kind"] == "single" and r["truth"] == [effect]]
        per_effect[effect] = {"n": len(rows), "right": sum(r["right"] for r in rows),
                              "accuracy": _fraction(sum(r["right"] for r in rows), len(rows)),
                              "false_named_elsewhere": sum(effect in r.get("false_named", [])
                                                           for r in records),
                              # the power curve: named right per band of D, below the limit too
                              "by_detectability": power_by_band(alone)}
    singles = [r for r in head if r["kind"] == "single"]
    pairs = [r for r in head if r["kind"] == "pair"]
    nones = [r for r in head if r["kind"] == "none"]
    below = [r for r in records if not r["headline"]]
    effectful = [r for r in head if r["kind"] != "none"]
    above = [r for r in head if not r.get("under_floor")]
    under = [r for r in head if r.get("under_floor")]
    return {
        "flights": len(records),
        "headline_flights": len(head),
        "overall": {"n": len(head), "accuracy": _fraction(sum(r["right"] for r in head), len(head))},
        "singles": {"n": len(singles), "accuracy": _fraction(sum(r["right"] for r in singles), len(singles))},
        "pairs": {"n": len(pairs), "accuracy": _fraction(sum(r["right"] for r in pairs), len(pairs))},
        "none": {"n": len(nones), "accuracy": _fraction(sum(r["right"] for r in nones), len(nones))},
        "false_effect_rate": _fraction(sum(r["false_effect"] for r in head), len(head)),
        # with the wrong members of an ambiguous group that holds a true effect counted false too
        "false_effect_rate_strict": _fraction(sum(r["false_effect_strict"] for r in head), len(head)),
        "failed": sum(r["failed"] for r in records),
        "ambiguous_hits": sum(r["ambiguous_hit"] for r in head),
        "below_limit": {"n": len(below), "accuracy": _fraction(sum(r["right"] for r in below), len(below))},
        "under_floor": {"n": len(under), "accuracy": _fraction(sum(r["right"] for r in under), len(under))},
        "above_floors": {
            kind: {"n": len(rows), "accuracy": _fraction(sum(r["right"] for r in rows), len(rows))}
            for kind, rows in (("overall", above), ("singles", [r for r in above if r["kind"] == "single"]),
                               ("pairs", [r for r in above if r["kind"] == "pair"]))},
        "shrink_median": _median([r["shrink"] for r in effectful if r["right"]]),
        # the same median for the prediction errors and for the library's bound (flights right)
        **{k + "_median": _median([r.get(k) for r in effectful if r["right"]]) for k in SHRINK_FIGURES},
        # the bound over every effect flight, named right or not
        "shrink_library_bound_median_all": _median([r.get("shrink_library_bound") for r in effectful]),
        "per_effect": per_effect,
        "by_detectability": _accuracy_by_band(records, "detectability"),
        # several flights per diagnosis: the same by the oracle's D over all of them
        **({"by_pooled_detectability": _accuracy_by_band(records, "pooled_detectability")}
           if any("pooled_detectability" in r for r in records) else {}),
    }


def _accuracy_by_band(records: list[dict], key: str) -> dict:
    """Effect diagnoses right per band of D (`key`), below-limit ones included."""
    return {
        f"{lo:g}-{hi:g}": {"n": len(rows), "accuracy": _fraction(sum(r["right"] for r in rows), len(rows))}
        for lo, hi in DETECTABILITY_BANDS
        for rows in [[r for r in records if r["kind"] != "none" and r.get(key) is not None
                      and lo <= r[key] < hi]]
    }
