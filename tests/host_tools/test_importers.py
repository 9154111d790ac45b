"""Importers: Betaflight (field table + real .bbl), PX4 ULog and tlog (synthetic files
built here), CSV v1, format detection and the `convert` command."""

from __future__ import annotations

import argparse
import math
import struct
from pathlib import Path

import numpy as np
import pytest

from propid.errors import UserError
from propid.flightlog import parse_vehicle, read_flightlog, read_vehicle, write_flightlog
from propid.importers import detect_format, import_log
from propid.importers.betaflight import convert_betaflight
from propid.importers.motor_order import parse_motor_map

SHARED = Path(__file__).resolve().parents[2].parent / "shared"
BETAFLIGHT = SHARED / "data" / "real" / "betaflight"


def quad_vehicle(order: str = "betaflight"):
    """A quad X whose rotor order is Betaflight's (default) or a permutation of it."""
    rear_right = {"position": [-0.08, -0.08, 0.0], "yaw_sign": 1}
    front_right = {"position": [0.08, -0.08, 0.0], "yaw_sign": -1}
    rear_left = {"position": [-0.08, 0.08, 0.0], "yaw_sign": -1}
    front_left = {"position": [0.08, 0.08, 0.0], "yaw_sign": 1}
    rotors = {
        "betaflight": [rear_right, front_right, rear_left, front_left],
        # front-right first, counter-clockwise seen from above
        "ccw": [front_right, front_left, rear_left, rear_right],
    }[order]
    return parse_vehicle({"name": "q", "mass": 0.6, "inertia": [3e-3, 3e-3, 5e-3], "rotors": rotors,
                          "kf_nominal": 5e-6, "km_nominal": 1e-7})


def betaflight_table(n: int = 50, poles: int = 14, high_res: bool = False):
    rng = np.random.default_rng(3)
    scale = 10 if high_res else 1
    fields = {
        "loopIteration": np.arange(n) * 4.0,
        "time": 31_886_040 + np.arange(n) * 984.0,
        "gyroADC[0]": rng.integers(-200, 200, n) * scale,
        "gyroADC[1]": rng.integers(-200, 200, n) * scale,
        "gyroADC[2]": rng.integers(-200, 200, n) * scale,
        "accSmooth[0]": rng.integers(-100, 100, n).astype(float),
        "accSmooth[1]": rng.integers(-100, 100, n).astype(float),
        "accSmooth[2]": np.full(n, 2048.0),
        "vbatLatest": np.full(n, 1160.0),
    }
    for m in range(4):
        fields[f"motor[{m}]"] = np.full(n, 48.0 + 1999.0 * (m + 1) / 10)
        fields[f"eRPM[{m}]"] = np.full(n, 1000.0 * (m + 1))  # eRPM / 100
    headers = {"motor_poles": poles, "acc_1G": 2048, "motor_pwm_protocol": 6, "motorOutput": [158, 2047],
               "blackbox_high_resolution": int(high_res)}
    return headers, fields


def test_betaflight_units_and_frame():
    headers, fields = betaflight_table()
    log, info = convert_betaflight(headers, fields, quad_vehicle())
    assert log.t[0] == 0.0 and log.t[1] == pytest.approx(984e-6)
    np.testing.assert_allclose(log.gyro[:, 0], fields["gyroADC[0]"] * math.pi / 180)  # FLU: no sign change
    np.testing.assert_allclose(log.gyro[:, 2], fields["gyroADC[2]"] * math.pi / 180)
    # eRPM field 1000 = 100,000 eRPM = 100,000/7 rpm for 14 poles
    assert log.rotor_speed[0, 0] == pytest.approx(100_000 / 7 * 2 * math.pi / 60)
    assert log.acc[0, 2] == pytest.approx(9.80665)
    assert log.extra["cmd_1"][0] == pytest.approx(0.1) and log.extra["cmd_4"][0] == pytest.approx(0.4)
    assert log.extra["vbat"][0] == pytest.approx(11.6)
    assert info["motor_map"] == [1, 2, 3, 4]


def test_betaflight_high_resolution_and_pole_count():
    headers, fields = betaflight_table(poles=12, high_res=True)
    log, _ = convert_betaflight(headers, fields, None)
    np.testing.assert_allclose(log.gyro[:, 1], fields["gyroADC[1]"] / 10 * math.pi / 180)
    assert log.rotor_speed[0, 1] == pytest.approx(200_000 / 6 * 2 * math.pi / 60)


def test_betaflight_motor_order_follows_vehicle_file():
    headers, fields = betaflight_table()
    log, info = convert_betaflight(headers, fields, quad_vehicle("ccw"))
    # vehicle rotors: front-right (BF motor 2), front-left (4), rear-left (3), rear-right (1)
    assert info["motor_map"] == [2, 4, 3, 1]
    per_motor = [1000.0 * (m + 1) * 100 / 7 * 2 * math.pi / 60 for m in range(4)]
    np.testing.assert_allclose(log.rotor_speed[0], [per_motor[1], per_motor[3], per_motor[2], per_motor[0]])
    explicit, info = convert_betaflight(headers, fields, quad_vehicle("ccw"), motor_map=parse_motor_map("1,2,3,4", 4))
    assert info["motor_map"] == [1, 2, 3, 4]
    np.testing.assert_allclose(explicit.rotor_speed[0], per_motor)


def test_betaflight_without_erpm_or_poles_is_a_clear_error():
    headers, fields = betaflight_table()
    no_rpm = {k: v for k, v in fields.items() if not k.startswith("eRPM")}
    with pytest.raises(UserError, match="bidirectional DShot"):
        convert_betaflight(headers, no_rpm)
    with pytest.raises(UserError, match="motor_poles"):
        convert_betaflight({**headers, "motor_poles": None}, fields)


def test_motor_map_parsing():
    assert parse_motor_map("2,1,4,3", 4) == [1, 0, 3, 2]
    with pytest.raises(UserError, match="exactly once"):
        parse_motor_map("1,1,3,4", 4)


@pytest.mark.skipif(not (BETAFLIGHT / "btfl_004.bbl").is_file(), reason="shared real data not present")
def test_real_betaflight_bbl_matches_reference_csv():
    vehicle = read_vehicle(BETAFLIGHT / "betaflight_quadx.vehicle.json")
    log, info = import_log(BETAFLIGHT / "btfl_004.bbl", "auto", vehicle, log_index=2)
    reference = read_flightlog(BETAFLIGHT / "btfl_004_log2.csv", vehicle)
    assert info["log_count"] == 2 and len(log) == len(reference) == 25031
    ours, theirs = log.columns(), reference.columns()
    assert set(ours) == set(theirs)
    for name, column in theirs.items():  # the CSV holds 6 significant digits
        np.testing.assert_allclose(ours[name], column, rtol=1e-5, atol=1e-5, err_msg=name)
    with pytest.raises(UserError, match="holds 2 log"):
        import_log(BETAFLIGHT / "btfl_004.bbl", "betaflight", vehicle, log_index=3)


# ----------------------------------------------------------------------------- ULog
def _ulog_message(kind: str, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), ord(kind)) + payload


def write_ulog(path: Path, gyro_t, gyro_frd, acc_frd, esc_t, esc_rpm) -> None:
    """A minimal valid ULog (header, flags, formats, subscriptions, data) written by hand."""
    out = bytearray(b"ULog\x01\x12\x35" + bytes([1]) + struct.pack("<Q", 0))
    out += _ulog_message("B", bytes(16) + struct.pack("<3Q", 0, 0, 0))
    out += _ulog_message("F", b"sensor_combined:uint64_t timestamp;float[3] gyro_rad;float[3] accelerometer_m_s2;")
    out += _ulog_message("F", b"esc_report:uint64_t timestamp;int32_t esc_rpm;float esc_voltage;")
    out += _ulog_message("F", b"esc_status:uint64_t timestamp;uint8_t esc_count;uint8_t[7] _padding0;esc_report[4] esc;")
    out += _ulog_message("A", struct.pack("<BH", 0, 0) + b"sensor_combined")
    out += _ulog_message("A", struct.pack("<BH", 0, 1) + b"esc_status")
    items = []
    for t, g, a in zip(gyro_t, gyro_frd, acc_frd):
        items.append((int(t), 0, _ulog_message("D", struct.pack("<HQ3f3f", 0, int(t), *g, *a))))
    for t, rpm in zip(esc_t, esc_rpm):
        body = struct.pack("<HQB7x", 1, int(t), len(rpm))
        for r in rpm:
            body += struct.pack("<Qif", int(t), int(r), 12.0)
        items.append((int(t), 1, _ulog_message("D", body)))
    for _, _, message in sorted(items, key=lambda item: (item[0], item[1])):
        out += message
    path.write_bytes(bytes(out))


def test_ulog_round_trip_frd_to_flu_and_px4_motor_order(tmp_path):
    rng = np.random.default_rng(4)
    gyro_t = 5_000_000 + np.arange(400) * 4000  # 250 Hz
    esc_t = 5_001_000 + np.arange(100) * 16000  # 62.5 Hz, own time base
    gyro_frd = rng.normal(0, 0.5, (400, 3)).astype(np.float32)
    acc_frd = np.tile([0.1, 0.2, -9.8], (400, 1)).astype(np.float32)
    esc_rpm = np.tile([10000, 11000, 12000, 13000], (100, 1)) + rng.integers(0, 500, (100, 4))
    path = tmp_path / "flight.ulg"
    write_ulog(path, gyro_t, gyro_frd, acc_frd, esc_t, esc_rpm)
    assert detect_format(path) == "ulog"
    # PX4 quad X: 1 front-right, 2 rear-left, 3 front-left, 4 rear-right; vehicle order is Betaflight's
    log, info = import_log(path, "auto", quad_vehicle())
    assert info["motor_map"] == [4, 1, 2, 3]
    gyro_rows = np.all(np.isfinite(log.gyro), axis=1)
    rotor_rows = np.all(np.isfinite(log.rotor_speed), axis=1)
    assert gyro_rows.sum() == 400 and rotor_rows.sum() == 100 and not np.any(gyro_rows & rotor_rows)
    np.testing.assert_allclose(log.t[gyro_rows], (gyro_t - gyro_t[0]) * 1e-6)
    np.testing.assert_allclose(log.t[rotor_rows], (esc_t - gyro_t[0]) * 1e-6)
    np.testing.assert_allclose(log.gyro[gyro_rows], gyro_frd * [1, -1, -1], rtol=1e-6)
    np.testing.assert_allclose(log.acc[gyro_rows][:, 2], 9.8, rtol=1e-6)
    rad = esc_rpm * 2 * math.pi / 60
    np.testing.assert_allclose(log.rotor_speed[rotor_rows], rad[:, [3, 0, 1, 2]])
    # a round trip through CSV keeps the event layout
    out = tmp_path / "flight.csv"
    write_flightlog(out, log)
    back = read_flightlog(out)
    np.testing.assert_allclose(back.rotor_speed, log.rotor_speed, rtol=1e-8, equal_nan=True)


def test_ulog_without_esc_status_says_what_to_log(tmp_path):
    path = tmp_path / "noesc.ulg"
    write_ulog(path, [1000, 2000], np.zeros((2, 3)), np.zeros((2, 3)), [], [])
    with pytest.raises(UserError, match="esc_status"):
        import_log(path, "ulog")


# ----------------------------------------------------------------------------- tlog
def test_tlog_round_trip(tmp_path):
    from propid import mavlink_io

    dialect = mavlink_io.dialect()
    mav = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = bytearray()
    rng = np.random.default_rng(5)
    gyro = rng.normal(0, 0.3, (200, 3))
    for k in range(200):
        t = 2_000_000 + k * 2000
        imu = dialect.MAVLink_highres_imu_message(t, 0.5, -0.2, -9.7, *gyro[k], 0, 0, 0, 0, 0, 0, 0, 0)
        frames += struct.pack(">Q", 1_700_000_000_000_000 + t) + imu.pack(mav)
        if k % 4 == 0:
            esc = dialect.MAVLink_esc_status_message(0, t + 700, [15000, -16000, 17000, 18000], [12.0] * 4, [3.0] * 4)
            frames += struct.pack(">Q", 1_700_000_000_000_000 + t) + esc.pack(mav)
    path = tmp_path / "flight.tlog"
    path.write_bytes(bytes(frames))
    assert detect_format(path) == "tlog"
    log, info = import_log(path, "auto", quad_vehicle())
    gyro_rows = np.all(np.isfinite(log.gyro), axis=1)
    rotor_rows = np.all(np.isfinite(log.rotor_speed), axis=1)
    assert gyro_rows.sum() == 200 and rotor_rows.sum() == 50
    np.testing.assert_allclose(log.gyro[gyro_rows], gyro * [1, -1, -1], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(log.acc[gyro_rows][0], [0.5, 0.2, 9.7], rtol=1e-6)
    np.testing.assert_allclose(log.rotor_speed[rotor_rows][0], np.array([15000, 16000, 17000, 18000]) * math.pi / 30)
    assert log.t[rotor_rows][0] == pytest.approx(700e-6)
    assert info["streams"] == "events"


# ----------------------------------------------------------------------------- CSV, detection, CLI
_BLACKBOX_HEADERS_ONLY = b"H Product:Blackbox flight data recorder by Nicholas Sherlock\nH Data version:2\n"


def test_blackbox_cut_in_its_headers_is_a_plain_error(tmp_path):
    # an SD-card log cut before its first frame: orangebox fails with an internal TypeError
    path = tmp_path / "cut.bbl"
    path.write_bytes(_BLACKBOX_HEADERS_ONLY)
    with pytest.raises(UserError, match="no data frame could be decoded: the log ends in or right after its headers"):
        import_log(path, "betaflight")


def test_blackbox_given_as_flightlog_says_convert_it(tmp_path):
    path = tmp_path / "flight.csv"
    path.write_bytes(_BLACKBOX_HEADERS_ONLY + b"H Firmware type:Cleanflight\n")
    with pytest.raises(UserError, match="a Betaflight blackbox log, not a flight-log CSV: convert it first"):
        read_flightlog(path)


def test_detect_format_rejects_unknown(tmp_path):
    path = tmp_path / "x.bin"
    path.write_bytes(b"\x00" * 64)
    with pytest.raises(UserError, match="give --format"):
        detect_format(path)


def _convert_args(argv):
    from propid.commands import convert

    parser = argparse.ArgumentParser()
    convert.add_arguments(parser)
    return convert, parser.parse_args(argv)


def test_convert_csv_normalises_and_copies_vehicle(tmp_path, capsys):
    vehicle_path = tmp_path / "q.vehicle.json"
    vehicle_path.write_text(
        '{"name": "q", "mass": 0.6, "inertia": [0.003, 0.003, 0.005], "kf_nominal": 5e-6, "km_nominal": 1e-7,'
        ' "rotors": [{"position": [-0.08, -0.08, 0], "yaw_sign": 1}, {"position": [0.08, -0.08, 0], "yaw_sign": -1},'
        ' {"position": [-0.08, 0.08, 0], "yaw_sign": -1}, {"position": [0.08, 0.08, 0], "yaw_sign": 1}]}'
    )
    source = tmp_path / "in.csv"
    source.write_text("t,gyro_x,gyro_y,gyro_z,omega_1,omega_2,omega_3,omega_4\n0,0,0,0,1,2,nan,4\n0.01,0,0,0,1,2,3,4.00\n")
    convert, args = _convert_args([str(source), "--vehicle", str(vehicle_path), "--out", str(tmp_path / "out.csv")])
    assert convert.run(args) == 0
    text = (tmp_path / "out.csv").read_text().splitlines()
    assert text[1].split(",")[6] == ""  # NaN written as an empty field
    assert (tmp_path / "out.vehicle.json").is_file()
    assert "wrote" in capsys.readouterr().out


def test_convert_rejects_bad_csv_with_line_number(tmp_path):
    source = tmp_path / "in.csv"
    source.write_text("t,gyro_x,gyro_y,gyro_z,omega_1\n0,0,0,0,1\n0.01,0,x,0,1\n")
    convert, args = _convert_args([str(source), "--out", str(tmp_path / "out.csv")])
    with pytest.raises(UserError, match="line 3, column gyro_y"):
        convert.run(args)
