"""propid gap's block folds with one or two logs (docs/gap.md, Scoring "Folds"): `--block-folds phases`
(evaluated, an option) numbers 1 s groups within each log from its own first row, in five partitions
whose grids are offset by 0.2 s, every held-out sum the mean over the partitions, each log's first
second held out whole; neither the order of the two logs nor where a log starts then picks which
blocks are held out together. The default "first-row" numbers the blocks across the logs in
canonical order: the order of the logs and each log's first row move every fold."""

from __future__ import annotations

import numpy as np
import pytest


def _flight_rows(rng, seconds, rate=100.0):
    n = int(round(seconds * rate))
    t = np.arange(n) / rate
    return t, rng.normal(size=(n, 2)), rng.normal(size=n)


def _design(parts, test_rows=20, rate=100.0):
    """Flights (t, x, y) stacked in the given order: 1 s fold groups from each flight's start, cut into
    test blocks of `test_rows` rows (whitening.split_rows), as whitening.apply_filters does."""
    from propid.gap.design import Design
    from propid.gap.whitening import split_rows

    parent, parent_flight, flight, times, xs, ys = [], [], [], [], [], []
    offset = 0
    for k, (t, x, y) in enumerate(parts):
        local = np.arange(t.size) // int(round(rate))  # 1 s from the flight's first row
        parent.append(local + offset)
        parent_flight += [k] * (local.max() + 1)
        offset += local.max() + 1
        flight.append(np.full(t.size, k))
        times.append(t)
        xs.append(x)
        ys.append(y)
    block, block_flight, group = split_rows(np.concatenate(parent), np.array(parent_flight), test_rows)
    return Design(axes=["roll"], names=["c0", "c1"], groups={"base": [0], "effect": [1]},
                  y={"roll": np.concatenate(ys)}, x={"roll": np.concatenate(xs)}, scale=np.ones(2), block=block,
                  flight=np.concatenate(flight), block_flight=block_flight, time=np.concatenate(times),
                  fold_group=group)


def _row_partitions(design, rule):
    """Per partition, the fold of every row keyed by (flight, time to 1e-6 s): what is held out together."""
    from propid.gap import scoring

    partitions, _ = scoring.fold_partitions(design, rule)
    out = []
    for fold in partitions:
        rows = fold[design.block]
        out.append({(int(f), round(float(t), 6)): int(k) for f, t, k in zip(design.flight, design.time, rows)})
    return out


def _canonical(assignment: dict, keys) -> tuple:
    """The partition of `keys` (fold labels renamed by first appearance): equal for equal partitions."""
    names = {}
    return tuple(names.setdefault(assignment[k], len(names)) for k in keys)


def test_the_folds_of_two_logs_do_not_depend_on_their_order():
    rng = np.random.default_rng(3)
    a, b = _flight_rows(rng, 11.3), _flight_rows(rng, 9.0)
    ab, ba = _design([a, b]), _design([b, a])

    def keyed(design, names):  # flight index -> the flight's name
        return [{(names[f], t): k for (f, t), k in p.items()} for p in _row_partitions(design, "phases")]

    first, second = keyed(ab, "ab"), keyed(ba, "ba")
    assert len(first) == 5
    keys = sorted(first[0])
    assert [_canonical(p, keys) for p in first] == [_canonical(p, keys) for p in second]
    # the rule before: the second log's blocks numbered after the first's, so the order moved the folds
    old_first = [{(("ab")[f], t): k for (f, t), k in p.items()} for p in _row_partitions(ab, "first-row")]
    old_second = [{(("ba")[f], t): k for (f, t), k in p.items()} for p in _row_partitions(ba, "first-row")]
    assert _canonical(old_first[0], keys) != _canonical(old_second[0], keys)


@pytest.mark.parametrize("steps", [1, 2, 3])
def test_a_log_trimmed_by_a_grid_offset_sees_the_same_set_of_partitions(steps):
    """A log whose first `steps` x 0.2 s are cut: on the rows both keep, the five partitions are the
    same five (in another order; test blocks of 0.2 s, so they line up). One grid ("first-row") moves."""
    rng = np.random.default_rng(4)
    t, x, y = _flight_rows(rng, 12.0)
    cut = 20 * steps
    whole = _design([(t, x, y)])
    trimmed = _design([(t[cut:], x[cut:], y[cut:])])
    # past the first 2 s (each log's first group, up to 1.8 s, is joined to hold its first second whole)
    keys = sorted(k for k in _row_partitions(trimmed, "phases")[0] if k[1] >= 2.0 + 0.2 * steps)
    for rule, same in (("phases", True), ("first-row", False)):
        full = {_canonical(p, keys) for p in _row_partitions(whole, rule)}
        cut_ = {_canonical(p, keys) for p in _row_partitions(trimmed, rule)}
        assert (full == cut_) is same


def test_each_log_s_first_second_is_held_out_whole_in_every_partition():
    from propid.gap import scoring

    rng = np.random.default_rng(7)
    design = _design([_flight_rows(rng, 9.0), _flight_rows(rng, 8.4)])
    partitions, _ = scoring.fold_partitions(design, "phases")
    rows = design.time < 1.0
    for fold in partitions:
        for f in (0, 1):
            assert np.unique(fold[design.block[rows & (design.flight == f)]]).size == 1


def test_every_block_is_held_out_once_in_every_partition_and_three_logs_keep_one_fold_each():
    from propid.gap import scoring

    rng = np.random.default_rng(5)
    two = _design([_flight_rows(rng, 7.5), _flight_rows(rng, 6.0)])
    partitions, groups = scoring.fold_partitions(two, "phases")
    assert partitions.shape == (scoring.FOLD_PHASES, two.n_blocks) and groups.shape == partitions.shape
    gr = scoring.grams(two, block_folds="phases")
    gr.weight = np.ones(1)
    stack = scoring.cv_sse_stack(gr, [0, 1])
    assert stack.shape == (5, two.n_blocks, 1) and np.all(stack > 0)
    assert np.allclose(scoring.cv_sse(gr, [0, 1]), stack.mean(axis=0))
    three = _design([_flight_rows(rng, 4.0) for _ in range(3)])
    partitions, _ = scoring.fold_partitions(three, "phases")
    assert partitions.shape == (1, three.n_blocks) and np.array_equal(partitions[0], three.block_flight)


def test_the_replication_test_is_on_the_partitions_mean():
    """paired_test on (R, B, A) stacks = the test on the means of each block's (weighted) sums."""
    from propid.gap import significance

    rng = np.random.default_rng(6)
    without = rng.uniform(1.0, 2.0, (5, 40, 2))
    with_ = without - rng.uniform(0.0, 0.2, (5, 40, 2))
    cross = rng.normal(scale=0.05, size=(5, 40, 2))
    weights = rng.uniform(0.5, 2.0, (5, 40, 2))
    stacked = significance.paired_test(without, with_, [0, 1], cross, weights)
    plain = significance.paired_test(without.mean(0), with_.mean(0), [0, 1], cross.mean(0))
    weighted = significance.paired_test((without * weights).mean(0), (with_ * weights).mean(0), [0, 1],
                                        (cross * weights).mean(0))
    assert stacked["value"] == pytest.approx(plain["value"])
    assert stacked["p_value"] == pytest.approx(weighted["p_value"])
    assert stacked["ci"] == pytest.approx(weighted["ci"])


def _sitl_log(sitl_binary, path, seed):
    """8 s of a crazyflie-plus (vehicle seed 104) flying with its CoM 8 % of the arm off-centre."""
    import subprocess

    subprocess.run([str(sitl_binary), "--quiet", "--duration", "8", "--vehicle", "crazyflie-plus", "--mode", "incorrect",
                    "--vehicle-seed", "104", "--seed", str(seed), "--log", str(path), "--effect", "com_offset=0.08"],
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120, check=True)
    return path


def _gap(monkeypatch, logs, vehicle, out):
    """propid gap on the logs in the order given (the canonical order bypassed, as a mirrored or
    re-exported pair whose content digests swap would order them)."""
    import json

    import propid.commands.gap as command
    import propid.gap.analysis as analysis
    from propid.cli import main

    monkeypatch.setattr(command, "canonical_order", lambda given: list(given))
    monkeypatch.setattr(analysis, "canonical_order", lambda given: list(given))
    args = [a for log in logs for a in ("--log", str(log))]
    assert main(["gap", *args, "--vehicle", str(vehicle), "--json", str(out), "--no-filter", "--quiet",
                 "--block-folds", "phases"]) == 0
    result = json.loads(out.read_text())
    return result["verdict"], sorted(result["significant"]), {e["id"]: e["explained_fraction"] for e in result["effects"]}


def test_two_sitl_logs_in_either_order_give_the_same_diagnosis(tmp_path, sitl_binary, monkeypatch):
    """With `--block-folds phases` the same two flights in both orders give the same verdict,
    significant set and held-out fractions (with "first-row" every fraction moved by up to 0.4 %: the
    second log's blocks fell into other folds)."""
    a, b = _sitl_log(sitl_binary, tmp_path / "a.csv", 208), _sitl_log(sitl_binary, tmp_path / "b.csv", 209)
    vehicle = tmp_path / "a.vehicle.json"
    ab = _gap(monkeypatch, [a, b], vehicle, tmp_path / "ab.json")
    ba = _gap(monkeypatch, [b, a], vehicle, tmp_path / "ba.json")
    assert ab[:2] == ba[:2]
    assert ab[2].keys() == ba[2].keys()
    for effect, fraction in ab[2].items():
        assert ba[2][effect] == pytest.approx(fraction, abs=1e-9), effect
    assert ab[0] == "com_offset"
