"""propid gap's reported held-out interval is the decision's own (docs/gap.md, Scoring): `ci` is the
two-sided 95 % interval of the statistic `held_out_p_value` tests (the block-weighted held-out sums, or the
prediction statistic with --replication prediction), centred on `held_out_weighted_fraction`, so it
excludes 0 exactly when the two-sided p is below 5 % and its lower edge is above 0 exactly when the
one-sided p is below 2.5 %. The unweighted interval reported before could contradict the p beside it."""

from __future__ import annotations

import numpy as np
import pytest

from test_gap_replication_statistic import _design


def _tests(design, statistic="improvement", weighted=True):
    """The replication test of the candidate as forward selection runs it, and the unweighted one."""
    from propid.gap import scoring, significance

    gr = scoring.grams(design)
    held0, held1 = scoring.cv_sse(gr, [0]), scoring.cv_sse(gr, [0, 1])
    cross = scoring.cv_cross(gr, [0], [0, 1])
    weights = significance.block_weights(held1, gr.count, design.fold_group) if weighted else None
    return (significance.paired_test(held0, held1, [0], cross, weights, statistic),
            significance.paired_test(held0, held1, [0], cross, None, statistic))


def _agrees(test) -> bool:
    """The interval and the one-sided p say the same: lower edge > 0 <=> p < 0.025, excludes 0 <=>
    two-sided p < 0.05, and it holds its centre."""
    lo, hi = test["ci"]
    p = test["p_value"]
    return ((lo > 0) == (p < 0.025) and ((lo > 0 or hi < 0) == (2.0 * min(p, 1.0 - p) < 0.05))
            and lo <= test["weighted_value"] <= hi)


@pytest.mark.parametrize("statistic", ["improvement", "prediction"])
def test_the_interval_excludes_zero_exactly_when_the_p_value_is_below_its_level(statistic):
    """Synthetic flights with a first second 10x louder (where the weighted and unweighted statistics
    part), strengths from none to clear: on every one the reported interval agrees with the p-value;
    the seeds span both sides of the level, and on some of them the unweighted interval (the one
    reported before) contradicts the weighted p, so the check can fail."""
    rng = np.random.default_rng(23)
    below = above = contradicted = 0
    for k in range(120):
        strength = (0.0, 0.05, 0.1, 0.15, 0.2, 0.3)[k % 6]
        test, plain = _tests(_design(rng, 1200, strength, loud_first_block=10.0), statistic)
        assert _agrees(test), (k, test)
        below += test["p_value"] < 0.025
        above += test["p_value"] >= 0.025
        contradicted += (plain["ci"][0] > 0) != (test["p_value"] < 0.025)
    assert below >= 10 and above >= 10
    assert contradicted >= 3


def test_without_weights_the_interval_is_the_unweighted_fractions():
    """No block weights (no fold groups): the tested statistic is the explained fraction itself and
    the interval is around it, in agreement with the p-value."""
    rng = np.random.default_rng(4)
    for strength in (0.0, 0.1, 0.3):
        test, plain = _tests(_design(rng, 1200, strength), weighted=False)
        assert test["weighted_value"] == test["value"] and test["ci"] == plain["ci"]
        assert _agrees(test)


def test_too_few_blocks_give_no_interval_and_no_evidence():
    from propid.gap import significance

    sse = np.ones((2, 1))
    test = significance.paired_test(sse, 0.5 * sse, [0])
    assert test["ci"] == [float("-inf"), float("inf")] and test["p_value"] == 1.0


def test_an_effect_entry_reports_the_interval_of_its_held_out_p_value():
    """selection.score (what OUT.json's effect entries carry): ci around held_out_weighted_fraction,
    in agreement with held_out_p_value; the unweighted explained fraction beside them unchanged."""
    from propid.gap import scoring, selection

    rng = np.random.default_rng(8)
    design = _design(rng, 1200, 0.2, loud_first_block=10.0)
    design.groups["thrust_nonlinearity"] = [1]  # one roll column, one parameter: the candidate
    gr = scoring.grams(design)
    gr.weight = np.ones(1)
    held = scoring.cv_sse(gr, [0])
    s = selection.score(design, gr, [0], "thrust_nonlinearity", held)
    test, _ = _tests(design)
    assert s["held_out_weighted_fraction"] == test["weighted_value"] and s["ci"] == test["ci"]
    assert s["held_out_p_value"] == test["p_value"] and s["explained_fraction"] == test["value"]
    assert _agrees({"ci": s["ci"], "p_value": s["held_out_p_value"], "weighted_value": s["held_out_weighted_fraction"]})
