"""Which effects: forward selection on held-out residual, look-alikes, ambiguity.

Rule (docs/gap.md, "Which"):
1. start from the base model (plus the stream alignment if esc_delay was significant);
2. score every remaining testable effect added to the current model (held-out
   explained fraction of the current residual on the effect's axes, one-sided paired test
   over short held-out blocks with an autocorrelation-consistent variance, significance.py);
   significant = physical sign, fit inside its physical plausibility range, Wald test
   (one-sided where physics keeps the parameters >= 0: a one-sided t for one parameter, the
   chi-bar-square test of the orthant for several) rejected by
   Holm's step-down over the candidates of the step (family-wise level 5 %)
   and the held-out improvement confirmed (one-sided paired test, Holm at 5 % over the
   same candidates);
3. among the significant ones take the one explaining most of the residual summed over
   all axes (so one-axis and four-axis effects compete on one scale); the look-alikes of it
   that are also significant and whose score difference with it has an interval containing 0
   cannot be told apart from it: if one's columns contain the other's (nested), the one with
   fewer parameters is kept, else the best is kept; the whole group is listed in `ambiguous`;
4. repeat until nothing significant is left (at most MAX_EFFECTS effects);
5. backward check: every named effect must still be significant on top of all the others
   named (the same tests, Holm over the named effects); while one is not, the one with the
   largest Wald p-value is dropped (an effect named first whose share a later one explains
   with its own signature: e.g. a thrust-exponent's yaw column standing in for rotor inertia).
An effect not selected is reported with its score added to the final model.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from propid.gap import significance, scoring
from propid.gap.design import Design
from propid.gap.effects import CONDITIONED_ON, LOOK_ALIKES, by_id

MAX_EFFECTS = 4
SIGN_SIGMAS = 2.0
FAMILY_LEVEL = significance.FAMILY_LEVEL  # per selection step, over its candidates (Holm)
# Two rules for the torque-scale look-alikes, evaluated on the blind benchmark and not the
# default (docs/gap.md, SITL accuracy "Two look-alike rules"):
# RANGE_EDGE: the plausibility range judged with the estimate's uncertainty: an estimate outside
# its range by at most RANGE_EDGE_SIGMAS of the Wald test's (Newey-West sandwich) standard errors
# is "at the edge"; "winner": such an effect counts only where it is the best significant
# candidate of its step (it never keeps a look-alike out nor joins its group); "all": everywhere;
# "off" (the default): implausible.
RANGE_EDGE = "off"
RANGE_EDGE_SIGMAS = 2.0
# THRUST_SIGNATURE: a thrust exponent must predict the held-out thrust (its one signature its
# look-alikes do not have: the collective thrust against the accelerometer)
THRUST_SIGNATURE = False
THRUST_SIGNED = ("thrust_nonlinearity",)
SCALE_EFFECTS = ("inertia_error", "gyro_scale", "thrust_nonlinearity")
NESTED = {("inertia_error", "gyro_scale")}  # (smaller, larger): the larger's columns span the smaller's


def _axis_idx(design: Design, axes: tuple[str, ...]) -> list[int]:
    return [design.axes.index(a) for a in axes if a in design.axes]


def _look_alike(a: str, b: str) -> bool:
    return (a, b) in LOOK_ALIKES or (b, a) in LOOK_ALIKES


def score(design: Design, gr: scoring.Grams, current: list[int], effect_id: str,
          held_current: np.ndarray, candidates: int = 1, size_gr: scoring.Grams | None = None,
          bounds: dict | None = None, replication: str = "improvement", folds: str = "time") -> dict:
    cols = current + design.groups[effect_id]
    held = scoring.cv_sse(gr, cols)
    axes = by_id(effect_id).axes
    idx = _axis_idx(design, axes)
    all_idx = list(range(len(design.axes)))
    frac_all, _ = scoring.explained(held_current, held, all_idx, bootstrap=False)
    own = design.groups[effect_id]
    nonnegative = by_id(effect_id).nonnegative

    block_folds = int(design.block_flight.max()) + 1 < 3 if design.block_flight.size else True

    def evidence(given):
        rep = gr
        if folds == "excitation" and block_folds:
            # the replication's folds balanced by the effect's excitation (scoring.excitation_folds)
            fold = scoring.excitation_folds(gr, given, own, design.fold_group)
            if not np.array_equal(fold, gr.fold):
                rep = dataclasses.replace(gr, fold=fold, partitions=fold[None, :],
                                          groups=None if design.fold_group is None else design.fold_group[None, :])
        # per partition of the folds (scoring.fold_partitions): held-out sums and block weights,
        # the test on their mean over the partitions (significance.paired_test)
        held_given, held_with = scoring.cv_sse_stack(rep, given), scoring.cv_sse_stack(rep, given + own)
        groups = rep.groups if rep.groups is not None else [None] * held_with.shape[0]
        weights = np.stack([significance.block_weights(h, gr.count, g) for h, g in zip(held_with, groups)])
        test = significance.paired_test(held_given, held_with, idx, scoring.cv_cross_stack(rep, given, given + own),
                                        weights, replication)
        # one parameter that physics keeps >= 0: the physical-sign rule already makes the
        # alternative one-sided, so the test is too (docs/gap.md, Scoring)
        lm = significance.effect_test(gr, given, own, nonnegative=nonnegative)
        reason, edge = implausible(gr, given, own, design.scale[own], by_id(effect_id).params,
                                   (bounds or {}).get(effect_id), se=lm.get("se"))
        return test, lm, physical_sign(gr, given, own, nonnegative), (reason, edge)

    test, lm, physical, (reason, edge) = evidence(current)
    # an effect whose signature a shared nuisance also makes (CONDITIONED_ON: rotor_inertia and a
    # residual rotor-stream lag) must hold both alone and on top of the nuisance: the larger
    # p-values, both signs, both ranges (either fit may stand in for the other's error)
    nuisance = CONDITIONED_ON.get(effect_id)
    conditioned = None
    if nuisance in design.groups and not set(design.groups[nuisance]) & set(current):
        given = current + design.groups[nuisance]
        c_test, c_lm, c_physical, (c_reason, c_edge) = evidence(given)
        conditioned = {"on": nuisance, "p_value": c_lm["p_value"], "held_out_p_value": c_test["p_value"],
                       "explained_fraction": c_test["value"], "physical_sign": c_physical}
        if c_test["p_value"] > test["p_value"]:
            test = c_test
        if c_lm["p_value"] > lm["p_value"]:
            lm = c_lm
        physical = physical and c_physical
        reason = reason or c_reason
        edge = edge or c_edge
    # ci: the interval of the statistic held_out_p_value tests (the block-weighted held-out sums),
    # centred on held_out_weighted_fraction; frac (ranking, reports) stays the unweighted fraction
    frac, ci = test["value"], test["ci"]
    replicated = test["p_value"] <= significance.REPLICATION_LEVEL / max(candidates, 1)
    per_axis = {a: scoring.explained(held_current, held, [k], bootstrap=False)[0] for k, a in enumerate(design.axes)}
    # size on the unwhitened rows: the effect's share of the measured signal (physical relevance)
    size = scoring.effect_size(size_gr or gr, current, own, idx)
    cols = own
    floor = scoring.MIN_SCALE_EFFECT_SIZE if effect_id in SCALE_EFFECTS else 0.0
    # a thrust exponent is the one torque-scale effect measured against the accelerometer's
    # collective thrust: one that does not predict the held-out thrust better is a roll/pitch torque
    # gain, i.e. one of its look-alikes, not an exponent (THRUST_SIGNATURE rule, docs/gap.md)
    if THRUST_SIGNATURE and effect_id in THRUST_SIGNED and "thrust" in design.axes and not per_axis["thrust"] > 0.0:
        floor = np.inf
    return {"id": effect_id, "explained_fraction": frac, "ci": ci, "held": held, "effect_size": size,
            "explained_fraction_all_axes": frac_all,
            **({"conditioned_on": conditioned} if conditioned else {}),
            "per_axis": per_axis,
            "axes": [a for a in axes if a in design.axes],
            "physical_sign": physical, "p_value": lm["p_value"],
            "effect_test": {"statistic": lm["statistic"], "dof": lm["dof"]},
            **({"implausible": reason} if reason else {}),
            **({"at_range_edge": edge} if edge and reason is None else {}),
            # the family's multiplicity is applied by forward_select (Holm over the step's candidates)
            "held_out_p_value": test["p_value"], "held_out_weighted_fraction": test["weighted_value"],
            # replicated: the effect predicts blocks its fit did not see better than without it
            "admissible": bool(physical and reason is None and size >= floor),
            "significant": bool(physical and reason is None and size >= floor and replicated
                                and lm["p_value"] <= FAMILY_LEVEL / max(candidates, 1))}


def implausible(gr: scoring.Grams, current: list[int], effect_cols: list[int], scale: np.ndarray,
                names: tuple[str, ...], bounds: list[tuple[float, float]] | None,
                se: np.ndarray | None = None) -> tuple[str | None, str | None]:
    """(reason, edge): why the effect's fit is physically implausible, or None: a coefficient's
    all-data estimate outside its physical range (effects.py bounds, docs/gap.md). By default
    (RANGE_EDGE off) no standard-error margin: the point estimate is what the after-fit and the
    corrected vehicle use. `scale`: raw coefficient = scaled coefficient / scale.
    With RANGE_EDGE on, an effect whose estimates outside their ranges all lie within
    RANGE_EDGE_SIGMAS standard errors of them gets (None, edge text) instead. `se`: the effect's
    coefficients' standard errors (scaled columns; the Wald test's sandwich ones), by default
    the all-data fit's residual-variance ones (computed only then)."""
    if not bounds:
        return None, None
    theta = scoring.solve(gr, current + effect_cols, np.arange(gr.s.shape[0]))
    value = theta[len(current):] / scale
    outside = [(name, v, k) for k, (name, v, (lo, hi)) in enumerate(zip(names, value, bounds)) if not lo <= v <= hi]
    if not outside:
        return None, None
    name, v, k = outside[0]
    lo, hi = bounds[k]
    reason = f"implausible: {name} = {v:.3g} outside its physical range [{lo:.3g}, {hi:.3g}]"
    if RANGE_EDGE == "off":
        return reason, None
    if se is None:
        se = scoring.coefficients_with_se(gr, current + effect_cols)[1][len(current):]
    value_se = np.asarray(se) / np.abs(scale)
    near = all(bounds[k][0] - RANGE_EDGE_SIGMAS * value_se[k] <= v <= bounds[k][1] + RANGE_EDGE_SIGMAS * value_se[k]
               for _, v, k in outside)
    if near:
        return None, reason.replace("implausible: ", "at the edge of its range: ")
    return reason, None


def physical_sign(gr: scoring.Grams, current: list[int], effect_cols: list[int], nonnegative: tuple[int, ...]) -> bool:
    """False when a parameter that physics keeps >= 0 is fitted below 0 by more than
    SIGN_SIGMAS standard errors, or when none of them is above 0 (a damping, an inertia or a
    drag coefficient cannot be negative: such a fit is some other error taking its shape)."""
    if not nonnegative:
        return True
    theta, se = scoring.coefficients_with_se(gr, current + effect_cols)
    own = theta[len(current):]
    own_se = se[len(current):]
    values = [(own[k], own_se[k]) for k in nonnegative]
    if any(v < -SIGN_SIGMAS * e for v, e in values):
        return False
    return any(v > 0 for v, _ in values)


def backward_check(design: Design, gr: scoring.Grams, base_cols: list[int], selected: list[dict],
                   size_gr: scoring.Grams | None = None, bounds: dict | None = None,
                   replication: str = "improvement", folds: str = "time") -> dict:
    """Step 5 of the rule: drop (from `selected`, in place) the named effects that are not
    significant on top of all the other named ones, one at a time, largest Wald p first.
    Returns {dropped id: why}."""
    dropped = {}
    while len(selected) > 1:
        checks = []
        for s in selected:
            given = list(base_cols) + [c for o in selected if o is not s for c in design.groups[o["id"]]]
            checks.append(score(design, gr, given, s["id"], scoring.cv_sse(gr, given), len(selected),
                                size_gr, bounds, replication, folds))
        wald = significance.holm([c["p_value"] for c in checks], FAMILY_LEVEL)
        held = significance.holm([c["held_out_p_value"] for c in checks], significance.REPLICATION_LEVEL)
        failing = [(c["p_value"], k) for k, (c, w, h) in enumerate(zip(checks, wald, held))
                   if not (c["admissible"] and w and h)]
        if not failing:
            break
        _, k = max(failing)
        gone = selected.pop(k)
        dropped[gone["id"]] = {
            "reason": "not significant on top of the other named effects: " + ", ".join(s["id"] for s in selected),
            "p_value": checks[k]["p_value"], "held_out_p_value": checks[k]["held_out_p_value"],
            "admissible": checks[k]["admissible"]}
    return dropped


def forward_select(design: Design, gr: scoring.Grams, candidates: list[str], base_cols: list[int],
                   progress=None, size_gr: scoring.Grams | None = None, bounds: dict | None = None,
                   replication: str = "improvement", folds: str = "time") -> dict:
    """`bounds`: effect id -> physical range per coefficient (Effect.bounds of the context);
    `replication`: the held-out replication's statistic (significance.REPLICATION_STATISTICS);
    `folds`: the replication's folds (scoring.REPLICATION_FOLDS)."""
    if folds not in scoring.REPLICATION_FOLDS:
        raise ValueError(f"unknown replication folds {folds!r}")
    current = list(base_cols)
    held_current = scoring.cv_sse(gr, current)
    held_base = held_current
    selected: list[dict] = []
    ambiguous: list[dict] = []
    remaining = list(candidates)
    while remaining and len(selected) < MAX_EFFECTS:
        scores = [score(design, gr, current, e, held_current, len(remaining), size_gr, bounds, replication, folds)
                  for e in remaining]
        if progress:
            progress(len(scores))
        rejected = significance.holm([s["p_value"] for s in scores], FAMILY_LEVEL)
        replicated = significance.holm([s["held_out_p_value"] for s in scores], significance.REPLICATION_LEVEL)
        for s, r, h in zip(scores, rejected, replicated):
            s["significant"] = bool(s["admissible"] and r and h)
        good = sorted([s for s in scores if s["significant"]], key=lambda s: -s["explained_fraction_all_axes"])
        if RANGE_EDGE == "winner":  # an effect at its range's edge counts only as the step's winner
            for s in good[1:]:
                if "at_range_edge" in s:
                    s["significant"] = False
            good = good[:1] + [s for s in good[1:] if "at_range_edge" not in s]
        if not good:
            break
        best = good[0]
        # the whole group of significant look-alikes of the best that it cannot be told apart from
        group, diffs = [], {}
        for other in good[1:]:
            if not _look_alike(best["id"], other["id"]):
                continue
            idx = sorted(set(_axis_idx(design, tuple(best["axes"]))) | set(_axis_idx(design, tuple(other["axes"]))))
            diff = significance.difference_interval(held_current, best["held"], other["held"], idx)
            if diff[0] <= 0:
                group.append(other)
                diffs[other["id"]] = diff
        if group:
            keep = next((o for o in group if (o["id"], best["id"]) in NESTED), best)  # the smaller model
            nested = keep is not best
            ids = [keep["id"]] + [o["id"] for o in [best] + group if o is not keep]
            ambiguous.append({"candidates": ids, "kept": keep["id"],
                              "score_difference_ci": diffs[group[0]["id"]],
                              "score_difference_cis": diffs,
                              "reason": "look-alike effects whose held-out scores do not differ significantly"
                                        + (" (nested: the one with fewer parameters kept)" if nested else "")})
            best = keep
        best["step"] = len(selected) + 1
        selected.append(best)
        current = current + design.groups[best["id"]]
        held_current = best["held"]
        remaining.remove(best["id"])
        for amb in ambiguous:  # an ambiguous runner-up is not selected on its own afterwards
            for cand in amb["candidates"]:
                if cand in remaining and amb["kept"] == best["id"]:
                    remaining.remove(cand)
    dropped = backward_check(design, gr, base_cols, selected, size_gr, bounds, replication, folds)
    if dropped:
        current = list(base_cols) + [c for s in selected for c in design.groups[s["id"]]]
        held_current = scoring.cv_sse(gr, current)
    others = [score(design, gr, current, e, held_current, 1, size_gr, bounds, replication, folds) for e in candidates
              if e not in {s["id"] for s in selected}]
    for o in others:
        if o["id"] in dropped:
            o["dropped"] = dropped[o["id"]]
    for o in others:
        o["significant"] = False
    return {"selected": selected, "others": others, "ambiguous": ambiguous, "columns": current,
            "held_base": held_base, "held_final": held_current}
