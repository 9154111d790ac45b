"""One rule for every command's output paths (README.md, "Output files"): missing
directories are created when the output is written; a path that cannot be written (a part
of it is a file, a file output is a directory, a directory output is a file) is a one-line
error before any work. One test per kind of output: text/JSON, vehicle file, figure,
flight-log CSV, MAVLink recording, directory of results."""

from __future__ import annotations

import json
import socket
import stat
import threading
import time
from pathlib import Path

import pytest

from propid import cli, outputs
from propid.errors import UserError
from propid.flightlog import parse_vehicle, read_vehicle, write_vehicle
from test_data_safety import small_flight  # noqa: F401  (fixture: a 4 s synthetic log + vehicle file)


def _file_in_the_way(tmp_path: Path) -> Path:
    """A directory path one of whose parts is a regular file."""
    blocker = tmp_path / "blocker.txt"
    blocker.write_text("a file, not a directory\n")
    return blocker / "sub"


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    return err


# --------------------------------------------------------------------------- the helper
def test_check_accepts_missing_directories_without_creating_them(tmp_path):
    target = tmp_path / "a" / "b" / "out.json"
    assert outputs.check_writable(target, "--json") == target
    assert outputs.check_directory(tmp_path / "c" / "d", "--out") == tmp_path / "c" / "d"
    assert not (tmp_path / "a").exists() and not (tmp_path / "c").exists()  # created at the write, not the check
    outputs.write_text(target, "x\n")
    assert target.read_text() == "x\n"


def test_check_refuses_what_cannot_be_written(tmp_path):
    way = _file_in_the_way(tmp_path)
    with pytest.raises(UserError, match=r"cannot write --json .*: .*blocker.txt is not a directory"):
        outputs.check_writable(way / "out.json", "--json")
    with pytest.raises(UserError, match="blocker.txt is not a directory"):
        outputs.check_directory(way, "--out")
    with pytest.raises(UserError, match="it is a file, not a directory"):
        outputs.check_directory(tmp_path / "blocker.txt", "--out")
    with pytest.raises(UserError, match="it is a directory"):
        outputs.check_writable(tmp_path, "--json")
    with pytest.raises(UserError, match="cannot create directory"):
        outputs.make_directory(way)
    with pytest.raises(UserError, match="cannot create directory"):  # at the write: one line, too
        outputs.write_text(way / "out.json", "x")


@pytest.mark.skipif(hasattr(__import__("os"), "geteuid") and __import__("os").geteuid() == 0,
                    reason="root may write anywhere")
def test_check_refuses_a_directory_without_write_permission(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(stat.S_IRUSR | stat.S_IXUSR)
    try:
        with pytest.raises(UserError, match="permission denied"):
            outputs.check_writable(locked / "new" / "out.json", "--json")
    finally:
        locked.chmod(stat.S_IRWXU)


# --------------------------------------------------------------------------- text / JSON
def test_text_outputs_go_into_missing_directories(tmp_path, capsys):
    from test_table1 import DURATION, metrics, synthetic_columns

    from propid import table1

    source = tmp_path / "table1.json"
    source.write_text(json.dumps({"lissajous": {"filter": table1.aggregate([metrics(synthetic_columns())],
                                                                            DURATION)}}))
    out = tmp_path / "new" / "deeper" / "t.md"
    assert cli.main(["table1", str(source), "--out", str(out)]) == 0
    assert "| Lissajous |" in out.read_text()
    way = _file_in_the_way(tmp_path)
    assert cli.main(["table1", str(source), "--out", str(way / "t.md")]) == 1
    assert "blocker.txt is not a directory" in _one_line(capsys)


def test_replay_json_table_and_plot_go_into_missing_directories(small_flight, tmp_path, cfilter_available):  # noqa: F811
    new = tmp_path / "results" / "run1"
    assert cli.main(["replay", "--log", str(small_flight), "--json", str(new / "o.json"),
                     "--plot", str(new / "plots" / "o.png"), "--no-progress"]) == 0
    assert json.loads((new / "o.json").read_text())["kf"]
    assert (new / "plots" / "o.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_observability_json_is_checked_before_the_symbolic_work(tmp_path, capsys, monkeypatch):
    from propid import observability

    def never(*args, **kwargs):
        raise AssertionError("the analysis ran before the output was checked")

    monkeypatch.setattr(observability, "analyse", never)
    vehicle = tmp_path / "v.json"
    write_vehicle(vehicle, parse_vehicle({"name": "q", "inertia": [1.4e-5, 1.4e-5, 2.2e-5],
                                          "kf_nominal": 2e-8, "km_nominal": 7e-10,
                                          "rotors": [{"position": [0.04, 0, 0], "yaw_sign": 1},
                                                     {"position": [0, 0.04, 0], "yaw_sign": -1},
                                                     {"position": [-0.04, 0, 0], "yaw_sign": 1},
                                                     {"position": [0, -0.04, 0], "yaw_sign": -1}]}))
    assert cli.main(["observability", "--vehicle", str(vehicle), "--json",
                     str(_file_in_the_way(tmp_path) / "o.json")]) == 1
    assert "blocker.txt is not a directory" in _one_line(capsys)


# --------------------------------------------------------------------------- vehicle file
def test_vehicle_files_go_into_missing_directories(tmp_path, capsys):
    from test_gap import _plus_quad_vehicle_file

    vehicle = _plus_quad_vehicle_file(tmp_path)
    target = tmp_path / "calibrated" / "v2.json"
    write_vehicle(target, read_vehicle(vehicle))
    assert read_vehicle(target).rotor_count == 4
    # gap takes a --vehicle-out in a missing directory: the command goes on to the log (too short)
    log = tmp_path / "a.csv"
    log.write_text("t,gyro_x,gyro_y,gyro_z,omega_1,omega_2,omega_3,omega_4\n"
                   + "".join(f"{k * 0.01},0,0,0,1000,1000,1000,1000\n" for k in range(20)))
    assert cli.main(["gap", "--log", str(log), "--vehicle", str(vehicle), "--vehicle-out",
                     str(tmp_path / "new" / "v3.json"), "--json", str(tmp_path / "new" / "g.json"),
                     "--quiet"]) == 1
    assert "segment" in _one_line(capsys)
    assert not (tmp_path / "new").exists()  # nothing written: the analysis stopped
    for option in ("--vehicle-out", "--json", "--report"):
        assert cli.main(["gap", "--log", str(log), "--vehicle", str(vehicle), option,
                         str(_file_in_the_way(tmp_path) / "x.json"), "--quiet"]) == 1
        assert f"cannot write {option}" in _one_line(capsys)  # before the analysis


# --------------------------------------------------------------------------- figure
def test_figures_go_into_missing_directories(tmp_path, capsys):
    from test_table1 import DURATION, metrics, synthetic_columns

    from propid import table1

    source = tmp_path / "table1.json"
    source.write_text(json.dumps({"lissajous": {"filter": table1.aggregate([metrics(synthetic_columns())],
                                                                            DURATION)}}))
    png = tmp_path / "figures" / "t1.png"
    assert cli.main(["table1", str(source), "--png", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert cli.main(["table1", str(source), "--png", str(tmp_path / "t1.notafigure")]) == 1
    assert "name it *.png" in _one_line(capsys)
    # plot: the output is judged before the log is read
    assert cli.main(["plot", "--log", str(tmp_path / "absent.csv"), "--out",
                     str(_file_in_the_way(tmp_path) / "p.png")]) == 1
    assert "cannot write --out" in _one_line(capsys)


# --------------------------------------------------------------------------- flight-log CSV
def test_convert_refuses_a_file_in_the_way_before_converting(small_flight, tmp_path, capsys):  # noqa: F811
    assert cli.main(["convert", str(small_flight), "--out", str(_file_in_the_way(tmp_path) / "o.csv"),
                     "--no-progress"]) == 1
    assert "cannot write --out" in _one_line(capsys)
    out = tmp_path / "converted" / "today" / "o.csv"
    assert cli.main(["convert", str(small_flight), "--out", str(out), "--no-progress"]) == 0
    assert out.read_text().startswith("t,")


# --------------------------------------------------------------------------- recording
def test_log_records_into_missing_directories(tmp_path, free_udp_port):
    from test_mavlink_io import telemetry_frames

    port = free_udp_port()
    stop = threading.Event()

    def send():
        frames = telemetry_frames(5)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            while not stop.is_set():
                for frame in frames:
                    sock.sendto(frame, ("127.0.0.1", port))
                time.sleep(0.05)

    sender = threading.Timer(0.3, send)
    sender.start()
    tlog, csv_path = tmp_path / "flights" / "a" / "rec.tlog", tmp_path / "flights" / "b" / "rec.csv"
    try:
        code = cli.main(["log", "--connect", f"udp:127.0.0.1:{port}", "--tlog", str(tlog), "--csv", str(csv_path),
                         "--duration", "1.5", "--timeout", "10", "--quiet"])
    finally:
        stop.set()
        sender.join()
    assert code == 0
    assert tlog.stat().st_size > 0 and csv_path.read_text().startswith("t")


# --------------------------------------------------------------------------- directories of results
def _stand_in_sitl(tmp_path: Path) -> Path:
    fake = tmp_path / "fake_sitl"
    fake.write_text("#!/bin/sh\nexit 0\n")
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    return fake


@pytest.mark.parametrize("command, work, extra", [
    ("campaign", "propid.commands.campaign.run_campaign", []),
    ("table1-extended", "propid.table1_extended.run_extended", []),
    ("effects-demo", "propid.effects_demo.run_demo", []),
    ("damage-bench", "propid.damage_bench.run_bench", []),
    ("gap-bench", "propid.commands.gap_bench.run_bench", []),
    ("real-data", "propid.real_data.run_real_data", ["--reference-kf", "3.7e-8"]),
])
def test_result_directories_are_checked_before_the_flights(command, work, extra, tmp_path, capsys, monkeypatch):
    def never(*args, **kwargs):
        raise AssertionError("the work started before the output directory was checked")

    monkeypatch.setattr(work, never)
    argv = [command, "--out", str(_file_in_the_way(tmp_path)), *extra]
    if command == "real-data":
        (tmp_path / "data").mkdir()
        argv += ["--data", str(tmp_path / "data"), "--vehicle", str(tmp_path / "data" / "v.json")]
    else:
        argv += ["--sitl", str(_stand_in_sitl(tmp_path))]
    assert cli.main(argv) == 1
    assert "cannot write --out" in _one_line(capsys)
    argv[2] = str(tmp_path / "blocker.txt")  # the directory itself is a file
    assert cli.main(argv) == 1
    assert "it is a file, not a directory" in _one_line(capsys)


@pytest.mark.parametrize("command, option", [("damage-bench", "--png"), ("gap-bench", "--result")])
def test_file_outputs_of_the_benches_are_checked_before_the_flights(command, option, tmp_path, capsys,
                                                                    monkeypatch):
    monkeypatch.setattr("propid.damage_bench.run_bench" if command == "damage-bench"
                        else "propid.commands.gap_bench.run_bench",
                        lambda *a, **k: (_ for _ in ()).throw(AssertionError("work before the check")))
    assert cli.main([command, "--out", str(tmp_path / "out"), option, str(_file_in_the_way(tmp_path) / "x.png"),
                     "--sitl", str(_stand_in_sitl(tmp_path))]) == 1
    assert f"cannot write {option}" in _one_line(capsys)
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- an output over an input
def _tiny_gap_inputs(tmp_path: Path) -> tuple[Path, Path]:
    from test_gap import _plus_quad_vehicle_file

    log = tmp_path / "a.csv"
    log.write_text("t,gyro_x,gyro_y,gyro_z,omega_1,omega_2,omega_3,omega_4\n"
                   + "".join(f"{k * 0.01},0,0,0,1000,1000,1000,1000\n" for k in range(20)))
    return log, _plus_quad_vehicle_file(tmp_path)


def test_no_output_overwrites_an_input_file(small_flight, tmp_path, capsys, monkeypatch):  # noqa: F811
    """gap --json, table1 --out, observability --json and replay's outputs over the vehicle file
    beside the log used to overwrite what they read; every such case is a one-line error before
    the work, and the input is left as it was."""
    from test_table1 import DURATION, metrics, synthetic_columns

    from propid import bound_check, observability, table1

    def never(*args, **kwargs):
        raise AssertionError("the work ran although an output is one of the inputs")

    monkeypatch.setattr(observability, "analyse", never)
    monkeypatch.setattr(bound_check, "check_campaign", never)
    log, vehicle = _tiny_gap_inputs(tmp_path)
    source = tmp_path / "table1.json"
    source.write_text(json.dumps({"lissajous": {"filter": table1.aggregate([metrics(synthetic_columns())],
                                                                            DURATION)}}))
    (tmp_path / "campaign" / "logs").mkdir(parents=True)
    (tmp_path / "campaign" / "table1.json").write_text(source.read_text())
    beside = small_flight.with_name("small.vehicle.json")
    cases = [
        (["gap", "--log", str(log), "--vehicle", str(vehicle), "--json", str(log), "--quiet"], "--json", log),
        (["gap", "--log", str(log), "--vehicle", str(vehicle), "--json", str(vehicle), "--quiet"], "--json", vehicle),
        (["table1", str(source), "--out", str(source)], "--out", source),
        (["observability", "--vehicle", str(vehicle), "--json", str(vehicle)], "--json", vehicle),
        (["bound-check", str(tmp_path / "campaign"), "--json", str(tmp_path / "campaign" / "table1.json")],
         "--json", tmp_path / "campaign" / "table1.json"),
        (["replay", "--log", str(small_flight), "--table", str(beside), "--no-progress"], "--table", beside),
        (["convert", str(log), "--out", str(log), "--no-progress"], "--out", log),
    ]
    for argv, option, target in cases:
        before = target.read_bytes()
        assert cli.main(argv) == 1, argv
        err = _one_line(capsys)
        assert f"cannot write {option}" in err and "must not overwrite the input file" in err, err
        assert target.read_bytes() == before


def test_convert_checks_the_vehicle_file_it_copies_beside_the_output(small_flight, tmp_path, capsys):  # noqa: F811
    (tmp_path / "o.vehicle.json").mkdir()  # where the vehicle file would be copied
    assert cli.main(["convert", str(small_flight), "--vehicle", str(small_flight.with_name("small.vehicle.json")),
                     "--out", str(tmp_path / "o.csv"), "--no-progress"]) == 1
    assert "it is a directory" in _one_line(capsys)
    assert not (tmp_path / "o.csv").exists()
