"""Table 1 metrics on synthetic flights with known answers, aggregation, rendering,
and the campaign plumbing driven by a stand-in propid_sitl."""

from __future__ import annotations

import json
import math
import stat
import sys
from pathlib import Path

import numpy as np
import pytest

from propid import table1
from propid.errors import UserError

RATE = 500.0
DURATION = 10.0
KF_NOM = 2.3e-8
KM_NOM = 7.8e-10
SPEC = table1.ConvergenceSpec.from_uniform_truth(0.2, math.radians(1.0))


def synthetic_columns(*, x_err=0.0, y_amp=0.0, yaw_err_deg=0.0, ref_yaw=0.0,
                      coeff_converge_at=1.0, coeff_blip_at=None, bias_converge_at=3.0,
                      jump_at=None, flip_at=None) -> dict[str, np.ndarray]:
    """A 10 s, 500 Hz quad flight whose metrics are known in closed form."""
    t = np.arange(int(DURATION * RATE) + 1) / RATE
    n = t.size
    cols: dict[str, np.ndarray] = {"t": t}
    ref = {"x": np.sin(0.3 * t), "y": np.cos(0.2 * t), "z": np.full(n, 1.0)}
    cols["ref_px"], cols["ref_py"], cols["ref_pz"] = ref["x"], ref["y"], ref["z"]
    cols["px"] = ref["x"] + x_err
    # y error: y_amp sin(2 pi t), whole cycles -> RMSE y_amp / sqrt(2) (up to one sample)
    cols["py"] = ref["y"] + y_amp * np.sin(2 * np.pi * t)
    cols["pz"] = ref["z"].copy()
    if jump_at is not None:
        cols["pz"][t >= jump_at] += 1.5
    cols["ref_yaw"] = np.full(n, ref_yaw)
    yaw = ref_yaw + math.radians(yaw_err_deg)
    cols["qw"], cols["qx"], cols["qy"], cols["qz"] = (np.full(n, math.cos(yaw / 2)), np.zeros(n),
                                                      np.zeros(n), np.full(n, math.sin(yaw / 2)))
    if flip_at is not None:  # rolled 180 deg: upside down
        upside = t >= flip_at
        cols["qw"][upside], cols["qx"][upside], cols["qz"][upside] = 0.0, 1.0, 0.0
    rng = np.random.default_rng(3)
    for i in range(1, 5):
        cols[f"omega_{i}"] = np.full(n, 1800.0)
        true_kf = KF_NOM * rng.uniform(0.8, 1.2)
        true_km = KM_NOM * rng.uniform(0.8, 1.2)
        cols[f"true_kf_{i}"] = np.full(n, true_kf)
        cols[f"true_km_{i}"] = np.full(n, true_km)
        # before convergence: 10 % of nominal off; after: 0.5 % (threshold is 1.15 %)
        off = np.where(t < coeff_converge_at, 0.10, 0.005)
        if coeff_blip_at is not None and i == 3:
            off = off.copy()
            off[np.argmin(np.abs(t - coeff_blip_at))] = 0.05  # one sample outside, later
        cols[f"est_kf_{i}"] = true_kf + off * KF_NOM
        cols[f"est_km_{i}"] = true_km - off * KM_NOM
    for a, b in zip("xyz", (0.01, -0.005, 0.002)):
        cols[f"true_bg_{a}"] = np.full(n, b)
        if bias_converge_at is None:
            cols[f"est_bg_{a}"] = np.full(n, b + 0.003)
        else:
            cols[f"est_bg_{a}"] = b + np.where(t < bias_converge_at, 0.003, 0.0002)
    return cols


def metrics(cols, **kwargs):
    return table1.trial_metrics(cols, np.full(4, KF_NOM), np.full(4, KM_NOM), SPEC,
                                duration_s=DURATION, **kwargs)


def test_thresholds_follow_the_truth_distribution():
    # U(0.8, 1.2) has std 0.4/sqrt(12) = 0.11547; 0.1 of it
    assert SPEC.coeff_threshold_rel == pytest.approx(0.011547, rel=1e-4)
    # U(-1, 1) deg/s has std 0.57735 deg/s; 0.1 of it in rad/s
    assert SPEC.bias_threshold == pytest.approx(math.radians(0.057735), rel=1e-4)


def test_rmse_known_values():
    m = metrics(synthetic_columns(x_err=0.1, y_amp=0.2, yaw_err_deg=3.0))
    assert m["rmse_x"] == pytest.approx(0.1, rel=1e-9)
    assert m["rmse_y"] == pytest.approx(0.2 / math.sqrt(2), rel=1e-3)
    assert m["rmse_z"] == pytest.approx(0.0, abs=1e-12)
    assert m["rmse_yaw_deg"] == pytest.approx(3.0, rel=1e-6)
    assert m["stable"] and m["unstable_reason"] == ""


def test_yaw_error_wraps_around_pi():
    # reference 179 deg, vehicle at -179 deg: 2 deg apart, not 358
    m = metrics(synthetic_columns(ref_yaw=math.radians(179.0), yaw_err_deg=2.0))
    assert m["rmse_yaw_deg"] == pytest.approx(2.0, rel=1e-6)


def test_convergence_time_is_last_exit_from_the_band():
    m = metrics(synthetic_columns(coeff_converge_at=1.234, bias_converge_at=4.0))
    assert m["t_conv_coeff_s"] == pytest.approx(1.234, abs=1.0 / RATE)
    assert m["t_conv_bias_s"] == pytest.approx(4.0, abs=1.0 / RATE)
    # one estimate leaving the band once at t = 2.5 moves the time past it
    m = metrics(synthetic_columns(coeff_converge_at=0.5, coeff_blip_at=2.5))
    assert m["t_conv_coeff_s"] == pytest.approx(2.5 + 1.0 / RATE, abs=1e-9)
    # the blip (5 % of nominal) is inside the 10x wider sensitivity band (11.5 %), and
    # the 10 % start-up error too: the loose time is the start of the log
    assert m["t_conv_coeff_loose_s"] == 0.0


def test_never_converged_and_aggregate_censoring():
    never = metrics(synthetic_columns(bias_converge_at=None))
    assert never["t_conv_bias_s"] is None
    quick = metrics(synthetic_columns(bias_converge_at=2.0))
    row = table1.aggregate([never, quick], DURATION)
    assert row["t_conv_bias_s_unconverged"] == 1
    assert row["t_conv_bias_s"] == pytest.approx((DURATION + 2.0) / 2, abs=1e-2)


def test_convergence_time_helper_edges():
    t = np.arange(5) * 0.1
    assert table1.convergence_time(t, np.zeros(5, bool)) == 0.0
    assert table1.convergence_time(t, np.array([1, 1, 0, 1, 1], bool)) is None
    assert table1.convergence_time(t, np.array([1, 0, 1, 0, 0], bool)) == pytest.approx(0.3)


def test_unstable_detection():
    jumped = metrics(synthetic_columns(jump_at=6.0))
    assert not jumped["stable"] and "position error" in jumped["unstable_reason"]
    flipped = metrics(synthetic_columns(flip_at=4.0))
    assert not flipped["stable"] and "90 deg" in flipped["unstable_reason"]
    stopped = metrics(synthetic_columns(), diverged=True)
    assert not stopped["stable"] and "diverged" in stopped["unstable_reason"]
    cols = synthetic_columns()
    short = {name: values[: values.size // 2] for name, values in cols.items()}
    cut = metrics(short)
    assert not cut["stable"] and "log ends" in cut["unstable_reason"]


def test_commanded_step_is_not_instability():
    cols = synthetic_columns()
    t = cols["t"]
    # a 1.2 m reference step at 1 s the vehicle follows within 0.5 s
    cols["ref_px"] = cols["ref_px"] + np.where(t > 1.0, 1.2, 0.0)
    cols["px"] = cols["px"] + np.where(t > 1.0, 1.2 * (1 - np.exp(-(t - 1.0) / 0.2)), 0.0)
    assert metrics(cols)["stable"]
    # ... but the allowance is the step size, not more: 2.3 m off is unstable
    cols["py"] = cols["py"] + np.where(t > 5.0, 2.3, 0.0)
    assert not metrics(cols)["stable"]


def test_aggregate_averages_stable_flights_only():
    good_a = metrics(synthetic_columns(x_err=0.1))
    good_b = metrics(synthetic_columns(x_err=0.3))
    bad = metrics(synthetic_columns(x_err=0.5, jump_at=5.0))
    row = table1.aggregate([good_a, good_b, bad], DURATION)
    assert row["stable_pct"] == pytest.approx(200.0 / 3.0)
    assert row["rmse_x"] == pytest.approx(0.2, rel=1e-9)
    assert row["trials"] == 3 and row["stable_trials"] == 2


def test_missing_columns_and_bad_files(tmp_path):
    cols = synthetic_columns()
    del cols["est_km_2"]
    with pytest.raises(UserError, match="est_km_2"):
        metrics(cols)
    garbage = tmp_path / "bad.csv"
    garbage.write_text("t,px\n0.0,abc\n")
    with pytest.raises(UserError, match="not a number"):
        table1.read_log_columns(garbage)
    with pytest.raises(UserError, match="cannot read"):
        table1.read_log_columns(tmp_path / "missing.csv")
    not_table = tmp_path / "t.json"
    not_table.write_text('{"foo": 1}')
    with pytest.raises(UserError, match="not a Table 1"):
        table1.load_table(not_table)


def write_csv(path: Path, cols: dict[str, np.ndarray]) -> None:
    names = list(cols)
    data = np.column_stack([cols[name] for name in names])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.10g")


def test_csv_round_trip_and_nominals(tmp_path):
    cols = synthetic_columns(x_err=0.05)
    write_csv(tmp_path / "f.csv", cols)
    rotors = [{"position": [0.1 * x, 0.1 * y, 0.0], "yaw_sign": s}
              for x, y, s in ((1, -1, 1), (-1, -1, -1), (-1, 1, 1), (1, 1, -1))]
    (tmp_path / "f.vehicle.json").write_text(json.dumps({"rotors": rotors, "kf_nominal": KF_NOM,
                                                         "km_nominal": [KM_NOM] * 4}))
    back = table1.read_log_columns(tmp_path / "f.csv")
    kf, km = table1.read_nominal_coefficients(tmp_path / "f.vehicle.json", table1.rotor_count(back))
    m = table1.trial_metrics(back, kf, km, SPEC, duration_s=DURATION)
    assert m["rmse_x"] == pytest.approx(0.05, rel=1e-6)


def test_render_markdown_and_png(tmp_path):
    row = table1.aggregate([metrics(synthetic_columns(x_err=0.1234))], DURATION)
    table = {"lissajous": {"filter": row}}
    text = table1.render_markdown(table)
    assert "| Lissajous | Filter | 0.123 (0.064)" in text
    assert "(12.020)" in text  # the paper's yaw beside ours
    assert "Circle" not in text  # only cells present are rendered
    png = tmp_path / "t.png"
    table1.render_png(table, png)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_output_under_a_file_is_a_one_line_error(tmp_path, capsys):
    from propid.cli import main

    row = table1.aggregate([metrics(synthetic_columns(x_err=0.1234))], DURATION)
    source = tmp_path / "table1.json"
    source.write_text(json.dumps({"lissajous": {"filter": row}}))
    for option in ("--out", "--png"):
        target = source / "t.png"  # a missing directory would be created; a file in the way cannot be
        assert main(["table1", str(source), option, str(target)]) == 1
        err = capsys.readouterr().err.strip()
        assert err.endswith(f"cannot write {option} {target}: {source} is not a directory") and "\n" not in err


FAKE_SITL = """\
#!{python}
# Stand-in for propid_sitl: writes a synthetic log whose x error depends on the mode.
import json, sys
sys.path.insert(0, {tests_dir!r})
import numpy as np
from test_table1 import synthetic_columns, write_csv
args = sys.argv[1:]
value = lambda name: args[args.index(name) + 1]
mode, seed, log = value("--mode"), int(value("--seed")), value("--log")
x_err = {{"oracle": 0.01, "incorrect": 0.2, "filter": 0.02}}[mode] * seed
cols = synthetic_columns(x_err=x_err, jump_at=5.0 if (mode == "incorrect" and seed == 2) else None)
write_csv(log, cols)
rotors = [{{"position": [0.1 * x, 0.1 * y, 0.0], "yaw_sign": s}} for x, y, s in ((1, -1, 1), (-1, -1, -1), (-1, 1, 1), (1, 1, -1))]
json.dump({{"rotors": rotors, "kf_nominal": {kf}, "km_nominal": {km}}}, open(log[:-4] + ".vehicle.json", "w"))
sys.exit(3 if (mode == "incorrect" and seed == 2) else 0)
"""


def test_campaign_with_a_stand_in_simulator(tmp_path):
    from propid.campaign import CampaignConfig, run_campaign

    fake = tmp_path / "fake_sitl"
    fake.write_text(FAKE_SITL.format(python=sys.executable, tests_dir=str(Path(__file__).parent),
                                     kf=KF_NOM, km=KM_NOM))
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    config = CampaignConfig(out_dir=tmp_path / "out", sitl=fake, trajectories=("circle",),
                            modes=("oracle", "incorrect"), trials=2, workers=2)
    table = run_campaign(config, progress=False)
    oracle, incorrect = table["circle"]["oracle"], table["circle"]["incorrect"]
    assert oracle["trials"] == 2 and oracle["stable_pct"] == 100.0
    assert oracle["rmse_x"] == pytest.approx((0.01 + 0.02) / 2, rel=1e-6)
    # seed 2 of incorrect "diverged": excluded from the mean, counted in % stable
    assert incorrect["stable_pct"] == 50.0
    assert incorrect["rmse_x"] == pytest.approx(0.2, rel=1e-6)
    saved = json.loads((tmp_path / "out" / "table1.json").read_text())
    assert saved["circle"]["oracle"]["per_trial"][0]["seed"] == 1
    assert "| Circle | Oracle |" in (tmp_path / "out" / "table1.md").read_text()
    assert not any((tmp_path / "out" / "logs").iterdir())  # logs deleted by default


def test_campaigns_share_one_pool_and_keep_their_own_tables(tmp_path):
    from dataclasses import replace

    from propid.campaign import CampaignConfig, run_campaign, run_campaigns

    fake = tmp_path / "fake_sitl"
    fake.write_text(FAKE_SITL.format(python=sys.executable, tests_dir=str(Path(__file__).parent),
                                     kf=KF_NOM, km=KM_NOM))
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    first = CampaignConfig(out_dir=tmp_path / "a", sitl=fake, trajectories=("circle",),
                           modes=("oracle", "incorrect"), trials=2, workers=2)
    second = replace(first, out_dir=tmp_path / "b", modes=("oracle",), trials=3)
    together = run_campaigns([first, second], progress=False)
    alone = [run_campaign(replace(config, out_dir=tmp_path / f"alone{k}"), progress=False)
             for k, config in enumerate((first, second))]
    for shared, single in zip(together, alone):
        for table in (shared, single):
            table.pop("_conditions")
            for cell in table["circle"].values():
                for trial in cell["per_trial"]:
                    trial.pop("wall_s", None)
        assert shared == single
    assert together[1]["circle"]["oracle"]["trials"] == 3
    assert "incorrect" not in together[1]["circle"]
    assert (tmp_path / "a" / "table1.json").is_file() and (tmp_path / "b" / "table1.md").is_file()


def test_campaign_command_carries_the_documented_conditions(tmp_path):
    from propid.campaign import CampaignConfig, Job, sitl_command

    config = CampaignConfig(out_dir=tmp_path, sitl=Path("/bin/true"), coeff_spread=0.2,
                            gyro_bias_max=math.radians(1.0))
    cmd = sitl_command(config, Job("circle", "filter", 3, 4), tmp_path / "x.csv")
    text = " ".join(cmd)
    assert "--paper" in cmd and "--start-at-rest" in cmd
    assert "--mode filter" in text and "--seed 4" in text and "--trajectory circle" in text
    # priors = the truth distribution's std: 0.2/sqrt(3) and 1 deg/s / sqrt(3)
    assert "--prior-kf-std 0.11547" in text and "--prior-km-std 0.11547" in text
    assert "--prior-bias-std 0.0100767" in text
    assert "--filter-rate-noise 0.0004" in text and "--prior-rate-std 0.01" in text
    library_rate_prior = CampaignConfig(out_dir=tmp_path, sitl=Path("/bin/true"), prior_rate_std=None)
    assert "--prior-rate-std" not in " ".join(
        sitl_command(library_rate_prior, Job("circle", "filter", 0, 1), tmp_path / "z.csv"))
    assert "--filter-coeff-walk 0.0" in text and "--incorrect-source nominal" in text
    library = CampaignConfig(out_dir=tmp_path, sitl=Path("/bin/true"), priors_from_truth=False,
                             prior_rate_std=None, filter_rate_noise=None, filter_coeff_walk=None, filter_bias_walk=None)
    text = " ".join(sitl_command(library, Job("step", "oracle", 0, 1), tmp_path / "y.csv"))
    assert "--prior" not in text and "--filter-" not in text


def test_campaign_cli_rate_prior_default_and_library(tmp_path, capsys):
    import argparse

    from propid.commands import campaign as campaign_command

    fake = tmp_path / "fake_sitl"
    fake.write_text(FAKE_SITL.format(python=sys.executable, tests_dir=str(Path(__file__).parent),
                                     kf=KF_NOM, km=KM_NOM))
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)

    def conditions(name, *extra):
        parser = argparse.ArgumentParser()
        campaign_command.add_arguments(parser)
        out = tmp_path / name
        args = parser.parse_args(["--out", str(out), "--sitl", str(fake), "--trajectories", "circle",
                                  "--modes", "oracle", "--trials", "1", "--no-progress", *extra])
        assert campaign_command.run(args) == 0
        return json.loads((out / "table1.json").read_text())["_conditions"]

    default = conditions("default")
    assert default["prior_rate_std"] == 0.01 and default["filter_rate_noise"] == 0.0004
    assert conditions("library", "--prior-rate-std", "0")["prior_rate_std"] is None  # 0 = library's
    with pytest.raises(UserError):
        conditions("negative", "--prior-rate-std", "-1")


def test_bound_ratio_is_a_dash_where_neither_converged():
    """'filter / bound' of two times that are both the flight duration on every flight (never reached) said
    1.00, as if the filter were at the bound; a cell where one of them converged keeps its ratio."""
    censored = {"trials": 3, "stable_trials": 3, "t_conv_coeff_s": 10.0, "t_conv_coeff_s_unconverged": 3,
                "t_bound_coeff_s": 10.0, "t_bound_coeff_s_unconverged": 3, "t_conv_bias_s": 4.0,
                "t_bound_bias_s": 10.0, "t_bound_bias_s_unconverged": 3}
    rows = table1.bound_rows({"step": {"filter": censored}})
    coeff_ratio, bias_ratio = rows[1][5], rows[1][9]
    assert coeff_ratio == "—" and bias_ratio == "0.40"
    assert "| — |" in table1.render_bound_markdown({"step": {"filter": censored}})


def test_cli_without_a_table_says_what_writes_it(tmp_path, monkeypatch, capsys):
    """`propid table1` alone reads build/results/table1.json; where there is none it says how to make one."""
    from propid.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["table1"]) == 1
    err = capsys.readouterr().err.strip()
    assert "make table1" in err and "propid campaign" in err and "\n" not in err
