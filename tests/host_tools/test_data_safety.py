"""The host tools never lose data and never pass a non-answer off as an answer: outputs
are kept when nothing arrives, arguments are judged before any work, bad input is a
one-line error (never a traceback), links that cannot work say so, and replay results
say what was used and when they cannot be trusted."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from propid import cli, mavlink_io
from propid.flightlog import FlightLog, parse_vehicle, write_flightlog, write_vehicle

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared"
BETAFLIGHT_BBL = SHARED / "data" / "real" / "betaflight" / "btfl_004.bbl"


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run_propid(*argv: str, stdin=None, timeout: float = 120.0) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO / "host_tools") + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.run([sys.executable, "-m", "propid.cli", *argv], capture_output=True, text=True,
                          timeout=timeout, env=env, stdin=stdin)


def one_line_error(proc: subprocess.CompletedProcess, *words: str) -> None:
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if "error:" in line]
    assert len(lines) == 1, proc.stderr
    for word in words:
        assert word in lines[0], lines[0]


@pytest.fixture()
def small_flight(tmp_path):
    """A 4 s rows log and its vehicle file, from the replay tests' synthetic quad."""
    from test_replay import VEHICLE, synthetic_log

    log_path = tmp_path / "small.csv"
    write_flightlog(log_path, synthetic_log(duration=4.0))
    write_vehicle(tmp_path / "small.vehicle.json", parse_vehicle(VEHICLE))
    return log_path


# --------------------------------------------------------------------------- log
def test_log_without_data_keeps_existing_outputs(tmp_path, capsys):
    tlog, csv_path = tmp_path / "keep.tlog", tmp_path / "keep.csv"
    tlog.write_bytes(b"yesterday's flight" * 100)
    csv_path.write_text("t,est_kf_1\n0,1\n")
    code = cli.main(["log", "--connect", f"udp:127.0.0.1:{free_udp_port()}", "--tlog", str(tlog),
                     "--csv", str(csv_path), "--timeout", "0.5", "--quiet"])
    assert code == 1 and "no MAVLink data" in capsys.readouterr().err
    assert tlog.read_bytes() == b"yesterday's flight" * 100
    assert csv_path.read_text() == "t,est_kf_1\n0,1\n"


def test_log_unwritable_output_fails_before_listening(tmp_path, capsys):
    (tmp_path / "no").write_text("a file where the directory should be\n")
    code = cli.main(["log", "--connect", f"udp:127.0.0.1:{free_udp_port()}", "--tlog",
                     str(tmp_path / "no" / "dir.tlog"), "--timeout", "30"])
    assert code == 1 and "is not a directory" in capsys.readouterr().err


@pytest.mark.parametrize("url, words", [("foo:bar", ("bad connection", "foo:bar")),
                                        ("udp:127.0.0.1:notaport", ("port 'notaport' is not a number",)),
                                        ("udp:127.0.0.1:70000", ("outside 1..65535",)),
                                        ("nocolon", ("bad connection",))])
def test_bad_connection_strings_are_named(url, words, capsys):
    assert cli.main(["log", "--connect", url, "--tlog", "x.tlog", "--timeout", "0.2"]) == 1
    err = capsys.readouterr().err
    assert "int()" not in err and "invalid literal" not in err
    for word in words:
        assert word in err


# --------------------------------------------------------------------------- listen
def test_listen_on_a_port_in_use_fails_clearly(capsys):
    port = free_udp_port()
    holder = mavlink_io.connect(f"udp:127.0.0.1:{port}")  # binds with SO_REUSEADDR, like pymavlink always does
    try:
        code = cli.main(["listen", "--connect", f"udp:127.0.0.1:{port}", "--timeout", "0.5"])
    finally:
        holder.close()
    assert code == 1 and "already in use" in capsys.readouterr().err


def test_listen_duration_without_sender_is_an_error(capsys):
    code = cli.main(["listen", "--connect", f"udp:127.0.0.1:{free_udp_port()}", "--duration", "0.5",
                     "--timeout", "10"])
    assert code == 1 and "no MAVLink data" in capsys.readouterr().err


def _vehicle_frames() -> list:
    """The fake vehicle's telemetry and HEARTBEAT, built before its thread starts: built inside it, a loaded
    machine could spend listen's whole --duration before the first HEARTBEAT went out."""
    from test_mavlink_io import heartbeat_frame, telemetry_frames

    return telemetry_frames(2) + [heartbeat_frame()]


def _fake_vehicle(port: int, frames: list, result: int, stop: threading.Event, received: list | None = None) -> None:
    """Sends `frames` (HEARTBEAT and propid telemetry) to `port`; answers MAV_CMD_PROPID_RESET with `result` (its
    param1 appended to `received`)."""
    d = mavlink_io.dialect()
    parser = d.MAVLink(None)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.settimeout(0.02)
        while not stop.is_set():
            for frame in frames:
                sock.sendto(frame, ("127.0.0.1", port))
            try:
                data = sock.recv(512)
            except (socket.timeout, ConnectionRefusedError):
                continue
            for msg in parser.parse_buffer(data) or []:
                if msg.get_type() == "COMMAND_LONG" and msg.command == d.MAV_CMD_PROPID_RESET:
                    if received is not None:
                        received.append(msg.param1)
                    ack = mavlink_io.encode_message("COMMAND_ACK", command=msg.command, result=result, progress=0,
                                                    result_param2=0, target_system=255, target_component=190)
                    sock.sendto(ack, ("127.0.0.1", port))


@pytest.mark.parametrize("result_name, code, rotor, param1, label", [
    ("MAV_RESULT_DENIED", 1, "2", 1.0, "rotor 2"), ("MAV_RESULT_ACCEPTED", 0, "2", 1.0, "rotor 2"),
    ("MAV_RESULT_ACCEPTED", 0, "all", -1.0, "all rotors")])
def test_listen_reset_exit_code_follows_the_acknowledgement(result_name, code, rotor, param1, label, capsys):
    """--reset takes the rotor as listen's screen numbers it (1..N) or all; the command carries the 0-based
    index (rotor 2 -> param1 1; it sent 2, the screen's rotor 3)."""
    port = free_udp_port()
    stop = threading.Event()
    result = getattr(mavlink_io.dialect(), result_name)
    received: list = []
    # Sending starts at once (frames to a port not yet bound are lost, and the next round arrives); --duration
    # leaves a loaded machine seconds for the HEARTBEAT, the command and its acknowledgement.
    vehicle = threading.Thread(target=_fake_vehicle, args=(port, _vehicle_frames(), result, stop, received))
    vehicle.start()
    try:
        got = cli.main(["listen", "--connect", f"udp:127.0.0.1:{port}", "--reset", rotor, "--duration", "4",
                        "--timeout", "10"])
    finally:
        stop.set()
        vehicle.join()
    captured = capsys.readouterr()
    assert f"MAV_CMD_PROPID_RESET {label}: {result_name}" in captured.out
    assert received and set(received) == {param1}
    assert got == code
    if code:
        assert "refused" in captured.err


@pytest.mark.parametrize("bad", ["0", "-2", "x", "1.5"])
def test_listen_reset_refuses_what_is_not_a_rotor_number(bad, capsys):
    with pytest.raises(SystemExit):
        cli.main(["listen", "--reset", bad, "--duration", "1"])
    assert "expected a rotor number 1..N" in capsys.readouterr().err


# --------------------------------------------------------------------------- convert
def test_convert_checks_arguments_before_writing(small_flight, tmp_path, capsys):
    out = tmp_path / "out.csv"
    out.write_text("precious\n")
    assert cli.main(["convert", str(small_flight), "--checks", "--out", str(out)]) == 1
    assert "--checks needs --vehicle" in capsys.readouterr().err
    assert cli.main(["convert", str(small_flight), "--log-index", "2", "--out", str(out)]) == 1
    assert "Betaflight" in capsys.readouterr().err
    assert out.read_text() == "precious\n"


@pytest.mark.skipif(not BETAFLIGHT_BBL.is_file(), reason="shared real data not present")
def test_convert_multi_log_blackbox_says_which_log(tmp_path):
    proc = run_propid("convert", str(BETAFLIGHT_BBL), "--out", str(tmp_path / "bf.csv"), "--no-progress",
                      timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "holds 2 logs" in proc.stderr and "converted log 1" in proc.stderr and "--log-index" in proc.stderr


# --------------------------------------------------------------------------- bad files
@pytest.mark.parametrize("content", [os.urandom(2048), '{"rotors": []}'.encode("utf-16"),
                                     b"\xff\xfe\x00garbage", b"\x80\x81 not utf-8"])
def test_binary_or_utf16_vehicle_file_is_one_line(small_flight, tmp_path, content):
    bad = tmp_path / "rand.bin"
    bad.write_bytes(content)
    one_line_error(run_propid("replay", "--log", str(small_flight), "--vehicle", str(bad), "--no-progress"),
                   "rand.bin")
    one_line_error(run_propid("convert", str(small_flight), "--vehicle", str(bad), "--out", str(tmp_path / "o.csv")),
                   "rand.bin")


def test_a_missing_vehicle_file_names_the_one_in_the_folder(small_flight, tmp_path, capsys):
    """A folder of logs with one vehicle file under another name (the shared real data's layout): replay and gap
    name that file in their error instead of only the X.vehicle.json they looked for."""
    (tmp_path / "small.vehicle.json").rename(tmp_path / "quad.vehicle.json")
    for argv in (["replay", "--log", str(small_flight), "--no-progress"],
                 ["gap", "--log", str(small_flight), "--no-filter", "--no-progress"]):
        assert cli.main(argv) == 1
        err = capsys.readouterr().err.strip()
        assert "small.vehicle.json" in err and str(tmp_path / "quad.vehicle.json") in err and "\n" not in err, err
    (tmp_path / "quad.vehicle.json").unlink()
    assert cli.main(["replay", "--log", str(small_flight), "--no-progress"]) == 1
    assert "the folder has" not in capsys.readouterr().err


def test_table1_on_a_binary_file_is_one_line(tmp_path):
    bad = tmp_path / "rand.bin"
    bad.write_bytes(os.urandom(4096))
    one_line_error(run_propid("table1", str(bad)), "rand.bin")


def test_broken_pipe_is_quiet(small_flight, tmp_path):
    """`propid ... | head -1`: the reader leaves early; no traceback, the shell's SIGPIPE code."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO / "host_tools") + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.Popen([sys.executable, "-m", "propid.cli", "replay", "--log", str(small_flight),
                             "--json", "-", "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env=env)
    proc.stdout.close()  # the reader is gone before the first line is written (head -0)
    _, err = proc.communicate(timeout=300)
    assert b"Traceback" not in err and b"BrokenPipe" not in err, err.decode()
    assert proc.returncode == 141


# --------------------------------------------------------------------------- replay
def test_replay_rejects_bad_flag_combinations_before_any_replay(small_flight, tmp_path):
    out = tmp_path / "out.json"
    start = time.monotonic()
    proc = run_propid("replay", "--log", str(small_flight), str(small_flight), "--band-table",
                      str(tmp_path / "b.md"), "--json", str(out), "--no-progress")
    one_line_error(proc, "--band-table/--band-plot need --checks")
    assert time.monotonic() - start < 30 and not out.exists()
    one_line_error(run_propid("replay", "--log", str(small_flight), "--plot", str(tmp_path / "p.jpg")), "PNG")
    one_line_error(run_propid("replay", "--log", str(small_flight), str(tmp_path / "absent.csv")), "absent.csv")
    (tmp_path / "nodir").write_text("a file where the directory should be\n")
    one_line_error(run_propid("replay", "--log", str(small_flight), "--json", str(tmp_path / "nodir" / "o.json")),
                   "is not a directory")


def test_replay_prints_a_rotor_table_and_json_only_where_asked(small_flight, tmp_path):
    proc = run_propid("replay", "--log", str(small_flight), "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert not any(line.startswith(("{", "}", '  "')) for line in proc.stdout.splitlines())  # no JSON unless --json
    assert "km [N m/(rad/s)^2]" in proc.stdout and "kf [N/(rad/s)^2]" in proc.stdout
    rows = [line.split() for line in proc.stdout.splitlines() if line.strip()[:1] in "1234"]
    assert [r[0] for r in rows] == ["1", "2", "3", "4"] and all("+-" in r for r in rows)
    proc = run_propid("replay", "--log", str(small_flight), "--json", "-", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)  # stdout is pure JSON; the report went to stderr
    assert len(summary["kf"]) == 4 and "kf [N/(rad/s)^2]" in proc.stderr
    # the km-combination line reads the JSON's stds in channel order, named by channel (right for X and plus)
    line = next(line for line in proc.stderr.splitlines() if "km combinations" in line)
    std = {name: f"{100 * value:.1f} %" for name, value in summary["km_combination_std"].items()}
    assert (f"mean km (yaw channel) {std['yaw']}, CW/CCW balance (collective) {std['collective']}, rotor "
            f"differences (roll, pitch channels) {std['roll']}, {std['pitch']}") in line


def _replay(log, options=None):
    from test_replay import VEHICLE

    from propid.replay import ReplayOptions, replay

    return replay(log, parse_vehicle(VEHICLE), options or ReplayOptions(progress=False)).summary


def test_replay_on_all_nan_gyro_fails(cfilter_available):
    from propid.errors import UserError
    from test_replay import synthetic_log

    log = synthetic_log(duration=3.0)
    blind = FlightLog(t=log.t, gyro=np.full_like(log.gyro, np.nan), rotor_speed=log.rotor_speed, extra={})
    with pytest.raises(UserError, match="no finite gyro"):
        _replay(blind)


def test_replay_warns_on_low_stream_rates(cfilter_available):
    """50 Hz gyro and 20 Hz rotor speeds (held between samples): reported, with warnings."""
    from test_replay import synthetic_log

    full = synthetic_log(duration=20.0)  # 500 Hz
    keep = np.arange(0, len(full), 10)  # 50 Hz rows
    slow = full.select(keep)
    held = slow.rotor_speed.copy()
    for k in range(held.shape[0]):  # rotor speeds at 20 Hz: 2.5 rows per sample, held
        held[k] = slow.rotor_speed[int(k // 2.5 * 2.5)]
    s = _replay(FlightLog(t=slow.t, gyro=slow.gyro, rotor_speed=held, extra={}))
    assert s["gyro_rate_hz"] == pytest.approx(50.0, rel=0.05)
    assert s["rotor_rate_hz"] < 25.0
    assert any("gyro at 50 Hz" in w for w in s["warnings"])
    assert any("rotor speeds at" in w for w in s["warnings"])
    fast = _replay(synthetic_log(duration=4.0))
    assert fast["warnings"] == []


def test_noise_values_used_are_recorded(cfilter_available):
    from propid.cfilter import DEFAULT_TUNING
    from propid.replay import ReplayOptions
    from test_replay import synthetic_log

    log = synthetic_log(duration=6.0)
    auto = _replay(log, ReplayOptions(noise="auto", progress=False))
    default = _replay(log, ReplayOptions(noise="default", progress=False))
    for key in ("gyro_noise_density", "gyro_sample_rate_hz", "rate_process_noise"):
        assert key in auto["config"] and key in default["config"]
        assert default["config"][key] == DEFAULT_TUNING[key]
    assert auto["config"]["gyro_sample_rate_hz"] == pytest.approx(500.0)
    assert auto["config"]["rate_process_noise"] != default["config"]["rate_process_noise"]
    assert "measured on the log" in auto["config_notes"]["noise"]
    assert default["config_notes"]["noise"] == "library defaults"
    # a log too short to measure on: 'auto' must not claim a measurement
    short = _replay(log.select(np.arange(len(log)) < 60), ReplayOptions(noise="auto", progress=False))
    assert "library defaults used" in short["config_notes"]["noise"]
    assert short["config"]["rate_process_noise"] == DEFAULT_TUNING["rate_process_noise"]


# --------------------------------------------------------------------------- plots
def test_plot_lines_break_across_skipped_segments():
    from propid.plotting import broken_at_gaps

    t = np.array([0.0, 0.01, 0.02, 5.0, 5.01, 5.02])
    y = np.arange(6.0)
    bt, by = broken_at_gaps(t, y)
    assert np.isnan(bt[3]) and np.isnan(by[3]) and bt.size == 7
    assert np.array_equal(broken_at_gaps(t[:3], y[:3])[0], t[:3])


def test_plot_title_names_vehicle_trajectory_and_effects(tmp_path):
    from propid import plotting
    from test_plot import sitl_like_csv

    csv_path = sitl_like_csv(tmp_path / "flight.csv", seconds=0.5)
    (tmp_path / "flight.summary.json").write_text(json.dumps(
        {"vehicle": "crazyflie", "trajectory": "circle", "effects": "esc_delay=0.01", "mode": "filter"}))
    flight = plotting.load_flight(csv_path)
    title = plotting.context_title(csv_path.name, flight.context)
    assert "vehicle crazyflie" in title and "trajectory circle" in title and "effects esc_delay=0.01" in title
    low, high = tmp_path / "low.png", tmp_path / "high.png"
    assert cli.main(["plot", "--log", str(csv_path), "--out", str(low), "--dpi", "40"]) == 0
    assert cli.main(["plot", "--log", str(csv_path), "--out", str(high), "--dpi", "160"]) == 0
    assert high.stat().st_size > 2 * low.stat().st_size


def test_plot_says_which_body_rate_is_drawn(tmp_path, monkeypatch):
    from propid import plotting
    from test_plot import sitl_like_csv

    titles = []
    real_savefig = plotting._pyplot().Figure.savefig

    def spy(fig, *args, **kwargs):
        titles.extend(ax.get_title(loc="left") for ax in fig.axes)
        return real_savefig(fig, *args, **kwargs)

    monkeypatch.setattr(plotting._pyplot().Figure, "savefig", spy)
    csv_path = sitl_like_csv(tmp_path / "flight.csv", seconds=0.5)
    plotting.plot_flight(plotting.load_flight(csv_path), tmp_path / "f.png")
    rate_titles = [t for t in titles if t.startswith("body rate:")]
    assert rate_titles and ("gyro" in rate_titles[0] or "truth" in rate_titles[0] or "estimate" in rate_titles[0])


def test_stream_rates_ignore_skipped_segments():
    """A 500 Hz log with a 10 s hole (ground segment left out) is still a 500 Hz log."""
    from propid.replay.run import stream_rates
    from test_replay import synthetic_log

    log = synthetic_log(duration=4.0)
    t = np.where(log.t < 2.0, log.t, log.t + 10.0)
    holed = FlightLog(t=t, gyro=log.gyro, rotor_speed=np.nan_to_num(log.rotor_speed, nan=500.0), extra={})
    rates = stream_rates(holed, np.arange(len(holed)))
    assert rates["gyro"] == pytest.approx(500.0, rel=0.01) and rates["rotor"] == pytest.approx(500.0, rel=0.01)


def test_a_missing_build_names_the_make_verb_that_builds_it(tmp_path):
    """`make` alone only lists the verbs; the advice must name the one that builds (make host)."""
    from propid.campaign import locate_sitl
    from propid.cfilter import load_library
    from propid.errors import UserError

    assert "\nhost:" in (REPO / "Makefile").read_text()
    with pytest.raises(UserError, match="build it with `make host`"):
        load_library(tmp_path / "libpropid_shared.so")
    with pytest.raises(UserError, match="build it with `make host`"):
        locate_sitl(str(tmp_path / "propid_sitl"))


def test_replay_report_prints_no_negative_zero_delay():
    """A replay as recorded (a delay of -0.0 s, or under half a millisecond of gyro lag) reads 'ESC delay 0 ms'."""
    import io

    from propid.commands.replay import report

    for delay in (-0.0, -0.0003, 0.0):
        summary = {"log": "flight.csv", "duration_s": 1.0, "rows_replayed": 10, "segment": "all", "gyro_rate_hz": 500.0,
                   "rotor_rate_hz": 500.0, "esc_delay_s": delay, "kf": [1.0], "kf_std": [0.1], "km": [1.0],
                   "km_std": [0.1], "kf_mean": [1.0], "km_mean": [1.0], "converged": {"kf": [True], "km": [True]},
                   "rejected": {}}
        out = io.StringIO()
        report(summary, out)
        assert "ESC delay 0 ms" in out.getvalue()


@pytest.mark.parametrize("argv", [("listen", "--timeout", "-1"), ("listen", "--duration", "0"),
                                  ("log", "--csv", "x.csv", "--timeout", "nan"),
                                  ("log", "--csv", "x.csv", "--stop-when-idle", "-2")])
def test_listen_and_log_refuse_times_that_are_not_positive(argv, tmp_path):
    """A time that is not > 0 is refused before any socket is opened (it used to wait 'within -1 s')."""
    proc = run_propid(*argv[:1], "--connect", "udp:127.0.0.1:1", *argv[1:])
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "must be a positive number of seconds" in proc.stderr and argv[-2] in proc.stderr
