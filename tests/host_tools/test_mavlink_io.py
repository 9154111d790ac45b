"""propid.mavlink_io: generated dialect, tlog writing/reading, damaged files,
message conversion, and the `propid log` / `propid listen` commands over UDP."""

from __future__ import annotations

import math
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from propid import cli, mavlink_io
from propid.errors import UserError

REPO = Path(__file__).resolve().parents[2]


# --------------------------------------------------------------------------
# Helpers: frames with known content
# --------------------------------------------------------------------------
def coefficients_frame(t_usec: int, seq: int = 0, scale: float = 1.0) -> bytes:
    kf = [2.3e-8 * scale * (1 + 0.01 * i) for i in range(4)] + [0.0] * 4
    km = [7.8e-10 * scale * (1 - 0.02 * i) for i in range(4)] + [0.0] * 4
    return mavlink_io.encode_message(
        "PROPID_COEFFICIENTS", sequence=seq, time_usec=t_usec,
        thrust_coeff=kf, thrust_coeff_std=[1e-10] * 4 + [0.0] * 4,
        drag_coeff=km, drag_coeff_std=[3e-12] * 4 + [0.0] * 4,
        thrust_coeff_converging=0x0F, thrust_coeff_converged=0x05,
        drag_coeff_converging=0x0A, drag_coeff_converged=0x02, rotor_count=4)


def gyro_frame(t_usec: int, seq: int = 0) -> bytes:
    return mavlink_io.encode_message(
        "PROPID_GYRO", sequence=seq, time_usec=t_usec,
        gyro_bias=[0.01, 0.02, 0.03], gyro_bias_std=[0.001, 0.002, 0.003],
        body_rate=[0.5, -0.25, 0.125], body_rate_std=[0.01] * 3,
        innovation=[0.0] * 3, innovation_test_ratio=[0.1] * 3, health=0x44)


def status_frame(t_usec: int, seq: int = 0) -> bytes:
    return mavlink_io.encode_message(
        "PROPID_STATUS", sequence=seq, time_usec=t_usec, health=0x44, gyro_accepted=1000,
        rotor_accepted=500, axis_gated=[1, 2, 3], gate_reopened=0, cov_repairs=4,
        state_clamps=0, resyncs=0, rejected_total=7, rejected=[0, 0, 0, 0, 7] + [0] * 11)


def heartbeat_frame(seq: int = 0) -> bytes:
    return mavlink_io.encode_message("HEARTBEAT", sequence=seq, type=2, autopilot=0,
                                     base_mode=0, custom_mode=0, system_status=4,
                                     mavlink_version=3)


def telemetry_frames(count: int = 20) -> list[bytes]:
    frames, seq = [], 0
    for k in range(count):
        t = 50_000 * k
        for make in (gyro_frame, status_frame, coefficients_frame):
            frames.append(make(t, seq))
            seq += 1
    frames.append(heartbeat_frame(seq))
    return frames


def write_tlog(path: Path, frames: list[bytes]) -> Path:
    with mavlink_io.TlogWriter(path) as writer:
        for k, frame in enumerate(frames):
            writer.write(frame, 1_700_000_000.0 + 0.01 * k)
    return path


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# --------------------------------------------------------------------------
# Dialect
# --------------------------------------------------------------------------
def test_dialect_has_our_messages_and_command():
    d = mavlink_io.dialect()
    assert d.MAVLINK_MSG_ID_PROPID_COEFFICIENTS == 53000
    assert d.MAVLINK_MSG_ID_PROPID_GYRO == 53001
    assert d.MAVLINK_MSG_ID_PROPID_STATUS == 53002
    assert d.MAV_CMD_PROPID_RESET == 53000
    # Our re-declared ESC_STATUS must keep the standard wire format (id 291, CRC extra 10).
    assert d.MAVLINK_MSG_ID_ESC_STATUS == 291
    assert d.MAVLink_esc_status_message.crc_extra == 10
    # Standard messages come along from common.xml.
    assert d.MAVLINK_MSG_ID_HIGHRES_IMU == 105


def test_health_flags_mirror_the_c_header():
    header = (REPO / "firmware" / "include" / "propid" / "propid.h").read_text()
    c_flags = {name: 1 << int(bit) for name, bit in
               re.findall(r"#define PROPID_HEALTH_(\w+)\s+\(1u << (\d+)\)", header)}
    assert len(c_flags) >= 8
    enum = mavlink_io.dialect().enums["PROPID_HEALTH_FLAGS"]
    xml_flags = {e.name.replace("PROPID_HEALTH_FLAGS_", ""): v for v, e in enum.items()
                 if not e.name.endswith("ENUM_END")}
    assert xml_flags == c_flags


def test_model_terms_mirror_the_c_header():
    # Every optional term the filter can report in propid_estimate_t.model_terms has its
    # name in the dialect, so `propid listen` and a ground station can show it.
    header = (REPO / "firmware" / "include" / "propid" / "propid.h").read_text()
    c_terms = {name: 1 << int(bit) for name, bit in
               re.findall(r"#define PROPID_TERM_(\w+)\s+\(1u << (\d+)\)", header)}
    assert len(c_terms) >= 6
    enum = mavlink_io.dialect().enums["PROPID_MODEL_TERMS"]
    xml_terms = {e.name.replace("PROPID_MODEL_TERMS_", ""): v for v, e in enum.items()
                 if not e.name.endswith("ENUM_END")}
    assert xml_terms == c_terms


def test_reject_reasons_mirror_the_c_status_codes():
    header = (REPO / "firmware" / "include" / "propid" / "propid.h").read_text()
    c_codes = {name: -int(value) for name, value in
               re.findall(r"PROPID_ERR_(\w+)\s*=\s*(-\d+)", header)}
    enum = mavlink_io.dialect().enums["PROPID_REJECT_REASON"]
    xml_codes = {e.name.replace("PROPID_REJECT_REASON_", ""): v for v, e in enum.items()
                 if not e.name.endswith(("ENUM_END", "_NONE"))}
    assert xml_codes == c_codes


def test_dialect_regenerates_when_the_xml_changes(tmp_path, monkeypatch):
    xml = tmp_path / "propid.xml"
    xml.write_text(mavlink_io.dialect_xml().read_text())
    monkeypatch.setenv("PROPID_MAVLINK_XML", str(xml))
    monkeypatch.setenv("PROPID_MAVLINK_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(mavlink_io, "_dialect_module", None)
    first = mavlink_io.dialect()
    assert not hasattr(first, "MAVLINK_MSG_ID_PROPID_TEST_EXTRA")

    xml.write_text(xml.read_text().replace(
        "</messages>",
        '<message id="53009" name="PROPID_TEST_EXTRA"><description>x</description>'
        '<field type="uint8_t" name="value">v</field></message></messages>'))
    monkeypatch.setattr(mavlink_io, "_dialect_module", None)
    second = mavlink_io.dialect()
    assert second.MAVLINK_MSG_ID_PROPID_TEST_EXTRA == 53009
    monkeypatch.setattr(mavlink_io, "_dialect_module", None)


def test_bad_dialect_xml_is_a_user_error(tmp_path, monkeypatch):
    xml = tmp_path / "propid.xml"
    xml.write_text("<mavlink><messages><message id='1'>")
    monkeypatch.setenv("PROPID_MAVLINK_XML", str(xml))
    monkeypatch.setenv("PROPID_MAVLINK_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(mavlink_io, "_dialect_module", None)
    with pytest.raises(UserError, match="mavgen failed"):
        mavlink_io.dialect()
    monkeypatch.setattr(mavlink_io, "_dialect_module", None)


# --------------------------------------------------------------------------
# tlog round trip and conversions
# --------------------------------------------------------------------------
def test_tlog_round_trip_fields_and_dict(tmp_path):
    path = write_tlog(tmp_path / "t.tlog", telemetry_frames(5))
    messages = list(mavlink_io.read_tlog(path))
    kinds = [m.get_type() for m in messages]
    assert kinds.count("PROPID_COEFFICIENTS") == 5
    assert kinds.count("HEARTBEAT") == 1
    coeffs = [m for m in messages if m.get_type() == "PROPID_COEFFICIENTS"][-1]
    d = mavlink_io.message_to_dict(coeffs)
    assert d["mavpackettype"] == "PROPID_COEFFICIENTS"
    assert d["time_usec"] == 200_000
    assert d["rotor_count"] == 4
    assert d["thrust_coeff"][1] == pytest.approx(2.3e-8 * 1.01, rel=1e-6)
    assert d["drag_coeff"][4:] == [0.0] * 4
    assert d["_sysid"] == 1 and d["_compid"] == 1
    # The tlog stamp of the frame is the receive time we wrote (to the 4 us the
    # format keeps for the link bits).
    assert d["_timestamp"] == pytest.approx(1_700_000_000.0 + 0.01 * 14, abs=1e-5)


def test_estimate_rows_convert_frd_back_to_flu(tmp_path):
    rows = []
    assembler = mavlink_io.EstimateRows()
    for msg in mavlink_io.read_tlog(write_tlog(tmp_path / "t.tlog", telemetry_frames(3))):
        row = assembler.feed(msg)
        if row is not None:
            rows.append(row)
    assert len(rows) == 3
    row = rows[-1]
    assert set(mavlink_io.estimate_columns(4)) <= set(row)
    assert row["t"] == pytest.approx(0.1)
    # FRD (0.01, 0.02, 0.03) -> FLU (0.01, -0.02, -0.03)
    assert (row["est_bg_x"], row["est_bg_y"], row["est_bg_z"]) == pytest.approx((0.01, -0.02, -0.03))
    assert (row["est_wx"], row["est_wy"], row["est_wz"]) == pytest.approx((0.5, 0.25, -0.125))
    assert row["std_bg_z"] == pytest.approx(0.003)
    assert row["health"] == 0x44
    assert row["rejected_total"] == 7 and row["gated_total"] == 6
    assert row["kf_converged"] == 0x05


def test_model_message_columns_are_flu(tmp_path):
    """PROPID_MODEL (optional terms) into the estimate rows: FRD back to FLU, the delay in s."""
    model = mavlink_io.encode_message(
        "PROPID_MODEL", time_usec=100_000, disturbance_torque=[1e-4, 2e-4, 3e-4],
        disturbance_torque_std=[1e-5, 2e-5, 3e-5], accel_bias=-0.3, accel_bias_std=0.05,
        accel_innovation=0.1, torque_scale=1.05, torque_scale_std=0.01, accel_accepted=10,
        accel_gated=1, delay_overflows=0, esc_delay_us=-12000, terms=1 | 2 | 4 | 16)
    frames = telemetry_frames(3)
    frames.insert(len(frames) - 2, model)  # before the last PROPID_COEFFICIENTS
    rows = []
    assembler = mavlink_io.EstimateRows()
    for msg in mavlink_io.read_tlog(write_tlog(tmp_path / "m.tlog", frames)):
        row = assembler.feed(msg)
        if row is not None:
            rows.append(row)
    assert all(math.isnan(row["est_dist_x"]) for row in rows[:-1])
    row = rows[-1]
    assert (row["est_dist_x"], row["est_dist_y"], row["est_dist_z"]) == pytest.approx((1e-4, -2e-4, -3e-4))
    assert row["std_dist_z"] == pytest.approx(3e-5)
    assert row["est_accel_bias_z"] == pytest.approx(0.3) and row["est_torque_scale"] == pytest.approx(1.05)
    assert row["esc_delay_s"] == pytest.approx(-0.012) and row["model_terms"] == 23
    from propid.commands.listen import format_model

    lines = format_model(mavlink_io.dialect().MAVLink(None).decode(bytearray(model)))
    assert "DISTURBANCE ACCEL TORQUE_SCALE ESC_DELAY" in lines[0] and "-12.0 ms" in lines[0]
    assert "accel z bias FLU +0.300" in "\n".join(lines)


def test_mavlogdump_decodes_our_tlog(tmp_path):
    path = write_tlog(tmp_path / "t.tlog", telemetry_frames(3))
    env = dict(os.environ)
    dumped = subprocess.run([sys.executable, "-m", "propid.mavlink_io", "mavlogdump", "--",
                             str(path)], capture_output=True, text=True, timeout=60, env=env)
    assert dumped.returncode == 0, dumped.stderr
    assert dumped.stdout.count("PROPID_COEFFICIENTS {") == 3
    assert "PROPID_STATUS {" in dumped.stdout and "HEARTBEAT {" in dumped.stdout
    # Plain mavlogdump, no dialect: standard messages still decode, ours are unknown.
    plain = subprocess.run([sys.executable, "-m", "pymavlink.tools.mavlogdump", str(path)],
                           capture_output=True, text=True, timeout=60, env=env)
    assert plain.returncode == 0, plain.stderr
    assert "HEARTBEAT {" in plain.stdout


def test_mavlogdump_of_a_missing_file_is_one_line(tmp_path, capsys):
    """pymavlink opens a path that is not a file as a serial port (a traceback without pyserial)."""
    from propid.mavlink_io import _main

    assert _main(["mavlogdump", "--", "--types", "PROPID_COEFFICIENTS", str(tmp_path / "missing.tlog")]) == 1
    err = capsys.readouterr().err.strip()
    assert err == f"error: cannot read {tmp_path / 'missing.tlog'}: no such file (mavlogdump reads a .tlog)"


# --------------------------------------------------------------------------
# Damaged files
# --------------------------------------------------------------------------
def test_missing_and_empty_files_are_user_errors(tmp_path):
    with pytest.raises(UserError, match="no such file"):
        list(mavlink_io.read_tlog(tmp_path / "absent.tlog"))
    empty = tmp_path / "empty.tlog"
    empty.write_bytes(b"")
    with pytest.raises(UserError, match="empty"):
        list(mavlink_io.read_tlog(empty))


def test_random_bytes_are_a_user_error(tmp_path):
    import random

    rng = random.Random(7)
    garbage = tmp_path / "garbage.tlog"
    # No 0xFD/0xFE start bytes at all, then with them sprinkled in: neither is a log.
    garbage.write_bytes(bytes(rng.randrange(0, 0xFD) for _ in range(20000)))
    with pytest.raises(UserError, match="no MAVLink frame"):
        list(mavlink_io.read_tlog(garbage))
    garbage.write_bytes(bytes(rng.randrange(0, 256) for _ in range(20000)))
    with pytest.raises(UserError):
        list(mavlink_io.read_tlog(garbage))


def test_truncated_tlog_keeps_complete_frames(tmp_path):
    full = write_tlog(tmp_path / "full.tlog", telemetry_frames(10))
    data = full.read_bytes()
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(data[:-30])  # ends inside the last frame
    report = mavlink_io.TlogReport(cut, cut.stat().st_size)
    messages = list(mavlink_io.read_tlog(cut, report=report))
    assert 25 <= len(messages) < 31
    assert report.trailing_bytes > 0
    assert any("truncated" in w for w in report.warnings())


def test_tlog_cut_before_the_first_frame_is_a_user_error(tmp_path):
    full = write_tlog(tmp_path / "full.tlog", telemetry_frames(1))
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(full.read_bytes()[:20])
    with pytest.raises(UserError):
        list(mavlink_io.read_tlog(cut))


def test_corrupt_frame_is_skipped_not_fatal(tmp_path):
    frames = telemetry_frames(10)
    data = bytearray(write_tlog(tmp_path / "ok.tlog", frames).read_bytes())
    # Flip a payload byte of the 5th frame (8-byte stamp + 10-byte header in).
    offset = sum(8 + len(f) for f in frames[:4]) + 8 + 14
    data[offset] ^= 0xFF
    damaged = tmp_path / "damaged.tlog"
    damaged.write_bytes(bytes(data))
    report = mavlink_io.TlogReport(damaged, len(data))
    messages = list(mavlink_io.read_tlog(damaged, report=report))
    assert len(messages) == len(frames) - 1
    assert report.bad_chunks >= 1


def test_cli_reports_bad_file_in_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.tlog"
    bad.write_bytes(b"this is not a tlog at all\n" * 100)
    code = cli.main(["plot", "--log", str(bad), "--out", str(tmp_path / "x.png")])
    err = capsys.readouterr().err
    assert code == 1
    assert "error:" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


# --------------------------------------------------------------------------
# Live commands over UDP on this machine
# --------------------------------------------------------------------------
def _send_frames(port: int, frames: list[bytes], repeat: int, stop: threading.Event,
                 period: float = 0.002) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for _ in range(repeat):
            for frame in frames:
                if stop.is_set():
                    return
                sock.sendto(frame, ("127.0.0.1", port))
                time.sleep(period)


def test_log_records_tlog_and_csv(tmp_path):
    from propid.commands import log

    port = free_udp_port()
    frames = telemetry_frames(10)
    stop = threading.Event()
    sender = threading.Thread(target=_send_frames, args=(port, frames, 1, stop, 0.001))
    timer = threading.Timer(0.3, sender.start)
    timer.start()
    try:
        recorder = log.record(f"udp:127.0.0.1:{port}", tmp_path / "r.tlog", tmp_path / "r.csv",
                              duration=20, timeout=10, stop_when_idle=0.7)
    finally:
        stop.set()
        timer.join()
        if sender.is_alive():
            sender.join()
    assert recorder.frames == len(frames)
    assert recorder.rows.count == 10
    decoded = list(mavlink_io.read_tlog(tmp_path / "r.tlog"))
    assert [bytes(m.get_msgbuf()) for m in decoded] == frames
    lines = (tmp_path / "r.csv").read_text().splitlines()
    assert lines[0].split(",") == mavlink_io.estimate_columns(4)
    assert len(lines) == 11


def test_log_times_out_with_a_clear_error(tmp_path, capsys):
    port = free_udp_port()
    code = cli.main(["log", "--connect", f"udp:127.0.0.1:{port}", "--tlog",
                     str(tmp_path / "x.tlog"), "--timeout", "0.5"])
    err = capsys.readouterr().err
    assert code == 1
    assert "no MAVLink data" in err


def _default_sigint() -> None:
    """In the child before exec: SIGINT back to its default disposition. A shell
    starts background jobs with SIGINT ignored and children inherit that; Python
    then installs no KeyboardInterrupt handler and the test's SIGINT would do
    nothing."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_log_interrupted_keeps_what_was_written(tmp_path):
    port = free_udp_port()
    tlog, csv_path = tmp_path / "i.tlog", tmp_path / "i.csv"
    proc = subprocess.Popen([sys.executable, "-m", "propid.cli", "log", "--connect",
                             f"udp:127.0.0.1:{port}", "--tlog", str(tlog), "--csv", str(csv_path),
                             "--timeout", "30", "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_default_sigint)
    stop = threading.Event()
    sender = threading.Thread(target=_send_frames,
                              args=(port, telemetry_frames(5), 1000, stop, 0.002))
    try:
        time.sleep(1.0)  # let the logger bind its port
        sender.start()
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and (not tlog.exists() or tlog.stat().st_size < 2000):
            time.sleep(0.1)
        time.sleep(1.2)  # past one flush period
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=20)
    finally:
        stop.set()
        if sender.is_alive():
            sender.join()
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "interrupted; kept" in err
    messages = list(mavlink_io.read_tlog(tlog))
    assert len(messages) > 20
    rows = csv_path.read_text().splitlines()
    assert rows[0].startswith("t,rotor_count,est_kf_1")
    assert len(rows) > 5


def test_listen_times_out_with_a_clear_error(capsys):
    port = free_udp_port()
    code = cli.main(["listen", "--connect", f"udp:127.0.0.1:{port}", "--timeout", "0.5"])
    assert code == 1
    assert "no MAVLink data" in capsys.readouterr().err


def _listen_while_sending(repeat: int, duration: float) -> tuple[int, str]:
    """`propid listen` for `duration` s while a sender starts 0.3 s in and sends the
    telemetry frames `repeat` times; (exit code, what listen printed is read by the caller)."""
    port = free_udp_port()
    stop = threading.Event()
    sender = threading.Thread(target=_send_frames, args=(port, telemetry_frames(5), repeat, stop, 0.002))
    timer = threading.Timer(0.3, sender.start)
    timer.start()
    try:
        return cli.main(["listen", "--connect", f"udp:127.0.0.1:{port}", "--timeout", "10",
                         "--duration", f"{duration:g}"])
    finally:
        stop.set()
        timer.join()
        if sender.is_alive():
            sender.join()


def test_listen_shows_estimates(capsys):
    code = _listen_while_sending(200, 1.5)
    out = capsys.readouterr().out
    assert code == 0
    view = out.strip().split("propid listen")[-1]
    assert "2.3000e-08" in view            # rotor 1 kf
    assert "converged" in view and "converging" in view
    assert "x +0.01000" in view and "y -0.02000" in view   # bias shown in FLU
    assert "health 0x44  GATED ALL_CONVERGED" in view


def test_listen_says_when_the_stream_goes_quiet(capsys):
    """After the sender stops, the screen says its figures are the last received, and a pipe
    gets that screen once, not the same screen every refresh."""
    code = _listen_while_sending(3, 3.5)
    out = capsys.readouterr().out
    assert code == 0
    screens = out.strip().split("propid listen")[1:]
    assert "2.3000e-08" in screens[-1]          # the last estimates are still shown
    assert "no propid message for" in screens[-1] and "last received" in screens[-1]
    assert not any("no propid message" in v for v in screens[:1])
    # quiet for ~2.5 s at a 0.5 s refresh: one quiet screen printed, then the final one
    assert sum("no propid message" in v for v in screens) == 2


def test_listen_plot_without_a_display_is_a_clear_error(monkeypatch, capsys):
    monkeypatch.setenv("MPLBACKEND", "Agg")
    import matplotlib

    monkeypatch.setattr(matplotlib, "get_backend", lambda: "agg")
    code = cli.main(["listen", "--plot", "--connect", f"udp:127.0.0.1:{free_udp_port()}",
                     "--timeout", "0.2"])
    assert code == 1
    assert "needs a display" in capsys.readouterr().err
