"""propid gap's held-out replication statistic (docs/gap.md, Scoring): the default improvement
(the held-out residual reduction) and the evaluated option "prediction" (the current model's held-out
residual along what the effect's training-fold fit predicts: mean 0 when the effect adds nothing,
degrees of freedom at most the noise's effective number of blocks)."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest


def _design(rng, n, strength, rate=100.0, test_rows=10, loud_first_block=1.0):
    """One axis: a base column, one smooth candidate (a random low-frequency mixture, as effect
    regressors are) present at `strength`, white unit noise; 1 s fold blocks cut into test blocks of
    `test_rows` rows (as whitening.whiten cuts them). `loud_first_block`: the first test block's noise
    that many times larger (a start transient's misfit)."""
    from propid.gap.design import Design
    from propid.gap.whitening import split_rows

    t = np.arange(n) / rate
    f = rng.uniform(0.1, 2.0, 4)
    ph = rng.uniform(0, 2 * np.pi, 4)
    c = np.sin(2 * np.pi * f[:, None] * t[None, :] + ph[:, None]).sum(axis=0)
    x = np.column_stack([rng.normal(size=n), c / c.std()])
    noise = rng.normal(size=n)
    noise[:test_rows] *= loud_first_block
    y = x[:, 0] + strength * x[:, 1] + noise
    parent = (t // 1.0).astype(int)
    block, block_flight, group = split_rows(parent, np.zeros(parent.max() + 1, dtype=int), test_rows)
    return Design(axes=["roll"], names=["c0", "c1"], groups={"base": [0]}, y={"roll": y}, x={"roll": x},
                  scale=np.ones(2), block=block, flight=np.zeros(n, dtype=int), block_flight=block_flight,
                  time=t, fold_group=group)


def _p(design, statistic):
    """The replication p-value of the candidate as forward selection computes it (block weights on)."""
    from propid.gap import scoring, significance

    gr = scoring.grams(design)
    held0, held1 = scoring.cv_sse(gr, [0]), scoring.cv_sse(gr, [0, 1])
    weights = significance.block_weights(held1, gr.count, design.fold_group)
    return significance.paired_test(held0, held1, [0], scoring.cv_cross(gr, [0], [0, 1]), weights,
                                    statistic)["p_value"]


def _bound(level, trials):
    return level + 2.6 * np.sqrt(level * (1 - level) / trials)


@pytest.mark.parametrize("statistic", ["improvement", "prediction"])
def test_replication_keeps_its_level_when_the_effect_adds_nothing(statistic):
    """Effect-free data, 300 seeds: the one-sided test rejects at 5 % on at most 5 % of them (+ 2.6
    Monte-Carlo standard errors). The prediction statistic's mean is 0 under the null (the
    training-fold fit does not see the held-out noise), the improvement's is below 0."""
    rng = np.random.default_rng(11)
    hits = sum(_p(_design(rng, 1200, 0.0), statistic) <= 0.05 for _ in range(300))
    assert hits / 300 <= _bound(0.05, 300)


def test_prediction_keeps_its_level_when_one_block_carries_the_excitation():
    """Effect-free, the candidate's column 30x larger in the first test block (a start transient
    excites it there), 300 seeds, at the level 0.005 (about a Holm bar of ten candidates): the noise
    of the sum is then mostly that block's; with the degrees of freedom capped at the noise's
    effective number of blocks (Kish) the level holds, with the block count's it does not."""
    from dataclasses import replace

    from propid.gap import significance

    rng = np.random.default_rng(12)
    designs = []
    for _ in range(300):
        d = _design(rng, 1200, 0.0)
        x = d.x["roll"].copy()
        x[:10, 1] *= 30.0
        designs.append(replace(d, x={"roll": x}))
    level, bound = 0.005, _bound(0.005, 300)
    capped = sum(_p(d, "prediction") <= level for d in designs)
    assert capped / 300 <= bound
    original = significance.effective_blocks
    try:
        significance.effective_blocks = lambda u: float(u.shape[0])  # the cap off
        uncapped = sum(_p(d, "prediction") <= level for d in designs)
    finally:
        significance.effective_blocks = original
    assert uncapped / 300 > bound


def test_effective_blocks_counts_where_the_noise_is():
    from propid.gap import significance

    assert significance.effective_blocks(np.array([1.0, -1.0] * 10)) == pytest.approx(20.0)
    one = np.zeros(40)
    one[0] = 5.0
    assert significance.effective_blocks(one) < 1.2


def test_prediction_confirms_weak_effects_the_improvement_misses():
    """A weak smooth effect (12 s at 100 Hz), 60 seeds: the prediction statistic keeps the effect's
    full t where the improvement's is about half of it (it charges the fit's noise), so it
    confirms it far more often at the Holm bar of eleven candidates."""
    rng = np.random.default_rng(13)
    designs = [_design(rng, 1200, 0.08) for _ in range(60)]
    bar = 0.05 / 11
    prediction = sum(_p(d, "prediction") <= bar for d in designs)
    improvement = sum(_p(d, "improvement") <= bar for d in designs)
    assert prediction >= improvement + 15


def test_an_unknown_statistic_is_refused():
    from propid.gap import significance

    z = np.ones((5, 1))
    with pytest.raises(ValueError):
        significance.paired_test(z, z, [0], statistic="median")


def test_forward_selection_takes_the_statistic_and_its_default_is_the_improvement():
    """forward_select's default equals replication="improvement" entry by entry; with "prediction"
    the held-out p-values are the prediction test's (a weak effect: smaller)."""
    from propid.gap import scoring, selection

    design = _design(np.random.default_rng(14), 1200, 0.08)
    design.groups["inertia_error"] = [1]
    gr = scoring.grams(design)
    gr.weight = np.ones(1)

    def held_p(**kw):
        out = selection.forward_select(design, gr, ["inertia_error"], [0], **kw)
        return [e["held_out_p_value"] for e in out["selected"] + out["others"]]

    assert held_p() == held_p(replication="improvement")
    assert held_p(replication="prediction")[0] < held_p()[0]


@pytest.fixture(scope="module")
def short_flight(sitl_binary, tmp_path_factory):
    """A 6 s default SITL flight's log (flown once for the option tests below)."""
    log = tmp_path_factory.mktemp("replication_options") / "f.csv"
    subprocess.run([str(sitl_binary), "--quiet", "--duration", "6", "--seed", "3", "--log", str(log)],
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120, check=True)
    return log


@pytest.mark.parametrize("option, keyword, value", [
    ("--replication", "replication", "improvement"),
    ("--replication", "replication", "prediction"),
    ("--replication-folds", "folds", "time"),
    ("--replication-folds", "folds", "excitation"),
])
def test_the_cli_option_reaches_forward_selection(option, keyword, value, short_flight, monkeypatch):
    """propid gap OPTION VALUE hands VALUE to forward selection as KEYWORD (the held-out
    replication's statistic, docs/gap.md Scoring; its folds, SITL accuracy)."""
    from propid.cli import main
    from propid.gap import selection

    seen = []

    def record(*args, **kwargs):
        seen.append(kwargs.get(keyword, "missing"))
        raise RuntimeError("stop after forward selection was reached")

    monkeypatch.setattr(selection, "forward_select", record)
    with pytest.raises(RuntimeError, match="stop after forward selection"):
        main(["gap", "--log", str(short_flight), "--vehicle", str(short_flight.with_name("f.vehicle.json")),
              "--no-filter", "--quiet", option, value])
    assert seen == [value]
