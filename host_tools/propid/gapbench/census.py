"""Why a diagnosis missed: for each true effect a wrong diagnosis did not name (a single's
verdict, one of a pair's top two), the rule of `propid gap` that decided it, read from
OUT.json alone; and what each false effect was. Counted over the headline flights, printed
under the bench's table (docs/gap-bench.md, "Where the accuracy is lost").

The causes, in the order they are checked (the first that applies is the cause):
- `run failed`: no OUT.json;
- `under a reporting floor`: the truth was drawn below a floor the tool applies on purpose
  (scoring.under_reporting_floor);
- `untestable`: a column or vehicle field the effect needs is missing (OUT.json `untestable`);
- `named, ranked below a look-alike` / `named, ranked below another effect`: named, not in
  the top one (single) or two (pair);
- `ambiguous with a look-alike`: only among an `ambiguous` entry's candidates;
- esc_delay: `lag fitted under the reporting floors` (|delay| at most max(a sample, 5 ms)),
  `lag shown, share under the 2 % floor`, `lag not shown` (the alignment's held-out evidence);
- `dropped by the backward check`;
- `plausibility range`, `physical sign`, `scale floor` (selection.py's admissibility rules);
- `on top of the residual lag`: passes alone, fails the test on top of the shared-lag columns;
- `Wald test`: the entry's Wald p-value above the first Holm bar, FAMILY_LEVEL / K (K the
  candidates scored; the entry's p-values are those on top of the final model);
- `held-out replication`: the same for its held-out p-value;
- `Holm order`: both p-values under the first bar, yet not selected (its bar at its rank or a
  later step).
False effects: `look-alike of a true effect` (effects.LOOK_ALIKES), `beside a true effect`,
`for a true effect` (no true effect named), `on an effect-free flight`.
"""

from __future__ import annotations

from collections import Counter

from propid.gap.effects import LOOK_ALIKES, MIN_REPORTED_LAG_S
from propid.gap.scoring import MIN_SCALE_EFFECT_SIZE
from propid.gap.selection import SCALE_EFFECTS
from propid.gap.significance import FAMILY_LEVEL, REPLICATION_LEVEL
from propid.gapbench.scoring import significant_ids, under_reporting_floor

NOT_REGRESSORS = ("esc_delay", "closed_loop_cancellation")
MIN_LAG_FRACTION = 0.02  # the alignment's reporting floor on its explained fraction (docs/gap.md)


def _look_alike(a: str, b: str) -> bool:
    return (a, b) in LOOK_ALIKES or (b, a) in LOOK_ALIKES


def _sample_period(result: dict) -> float:
    rates = [r for r in (result.get("inputs") or {}).get("rate_hz", []) if isinstance(r, (int, float)) and r > 0]
    return 1.0 / min(rates) if rates else 0.0


def _lag_cause(entry: dict, result: dict) -> str:
    delay = abs(float((entry.get("params") or {}).get("delay_s") or 0.0))
    if delay <= max(_sample_period(result), MIN_REPORTED_LAG_S):
        return "lag fitted under the reporting floors"
    ci = entry.get("ci") or [None, None]
    shown = entry.get("held_out_p_value") is not None or (ci[0] is not None and ci[0] > 0)
    if shown and entry.get("explained_fraction", 0.0) < MIN_LAG_FRACTION:
        return "lag shown, share under the 2 % floor"
    return "lag not shown"


def _p_above(value, bar: float) -> bool:
    return not isinstance(value, (int, float)) or value > bar


def miss_cause(effect: dict, result: dict, top: list[str]) -> str:
    """The rule that kept one true effect out of the diagnosis's top `len(top)` (see module text)."""
    eid = effect["id"]
    if under_reporting_floor(effect):
        return "under a reporting floor"
    if any(isinstance(u, dict) and u.get("id") == eid for u in result.get("untestable") or []):
        return "untestable"
    named = significant_ids(result)
    if eid in named:
        above = named[:named.index(eid)]
        return ("named, ranked below a look-alike" if any(_look_alike(eid, o) for o in above)
                else "named, ranked below another effect")
    if any(isinstance(a, dict) and eid in (a.get("candidates") or []) for a in result.get("ambiguous") or []):
        return "ambiguous with a look-alike"
    entries = {e.get("id"): e for e in result.get("effects") or [] if isinstance(e, dict)}
    entry = entries.get(eid)
    if entry is None:
        return "untestable"
    if eid == "esc_delay":
        return _lag_cause(entry, result)
    if "dropped" in entry:
        return "dropped by the backward check"
    if "implausible" in entry:
        return "plausibility range"
    if entry.get("physical_sign") is False:
        return "physical sign"
    if eid in SCALE_EFFECTS and entry.get("effect_size", 1.0) < MIN_SCALE_EFFECT_SIZE:
        return "scale floor"
    candidates = max(1, sum(1 for k in entries if k not in NOT_REGRESSORS))
    wald_bar, held_bar = FAMILY_LEVEL / candidates, REPLICATION_LEVEL / candidates
    cond = entry.get("conditioned_on")
    if (isinstance(cond, dict) and not _p_above(entry.get("p_value"), wald_bar)
            and not _p_above(entry.get("held_out_p_value"), held_bar)
            and (_p_above(cond.get("p_value"), wald_bar) or _p_above(cond.get("held_out_p_value"), held_bar)
                 or cond.get("physical_sign") is False)):
        return "on top of the residual lag"
    if _p_above(entry.get("p_value"), wald_bar):
        return "Wald test"
    if _p_above(entry.get("held_out_p_value"), held_bar):
        return "held-out replication"
    return "Holm order"


def flight_census(answer: dict, result: dict | None, record: dict) -> dict:
    """{"misses": [{"effect", "cause"}], "false": [{"effect", "kind"}]} for one flight."""
    if not isinstance(result, dict) or "verdict" not in result:
        return {"misses": [] if answer["kind"] == "none" else [{"effect": None, "cause": "run failed"}],
                "false": []}
    truth = [e["id"] for e in answer["effects"]]
    named = significant_ids(result)
    misses = []
    if not record.get("right") and answer["kind"] != "none":
        top = named[:1] if answer["kind"] == "single" else named[:2]
        misses = [{"effect": e["id"], "cause": miss_cause(e, result, top)}
                  for e in answer["effects"] if e["id"] not in top]
    false = []
    for eid in record.get("false_named") or []:
        if not truth:
            kind = "on an effect-free flight"
        elif any(_look_alike(eid, t) for t in truth):
            kind = "look-alike of a true effect"
        elif set(truth) & set(named):
            kind = "beside a true effect"
        else:
            kind = "for a true effect"
        false.append({"effect": eid, "kind": kind})
    return {"misses": misses, "false": false}


def summarize_census(censuses: list[dict], records: list[dict]) -> dict:
    """Counts over the headline flights: {"misses": {cause: n}, "false": {kind: n}}."""
    misses, false = Counter(), Counter()
    for census, record in zip(censuses, records):
        if not record.get("headline"):
            continue
        misses.update(m["cause"] for m in census["misses"])
        false.update(f["kind"] for f in census["false"])
    return {"misses": dict(misses.most_common()), "false": dict(false.most_common())}


def render_census(census: dict) -> str:
    lines = ["why true effects were missed (headline flights)          count"]
    lines += [f"  {cause:<55s}{n:>5d}" for cause, n in census.get("misses", {}).items()] or ["  none"]
    lines.append("false effects named (headline flights)                  count")
    lines += [f"  {kind:<55s}{n:>5d}" for kind, n in census.get("false", {}).items()] or ["  none"]
    return "\n".join(lines)
