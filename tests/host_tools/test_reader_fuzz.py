"""Property-based fuzzing of the host tools' readers (hypothesis): vehicle JSON,
flight-log CSV, MAVLink tlog, PX4 ULog and Betaflight blackbox (.bbl).

Property: whatever the bytes of the file, a reader either returns or raises
UserError with a one-line message (what the CLI prints as
"propid <cmd>: error: ..."); any other exception is a traceback for the user
and fails the test. Inputs are valid files mutated (bytes flipped, inserted,
deleted, truncated, fields replaced by odd values) and raw bytes behind each
format's magic. The run is deterministic (derandomized, fixed example count):
PROPID_FUZZ_EXAMPLES raises the count for a longer search.
"""

from __future__ import annotations

import json
import os
import struct
import sys
import tempfile
from pathlib import Path

import numpy as np

from hypothesis import HealthCheck, given, settings  # pinned in host_tools/setup/requirements.txt
from hypothesis import strategies as st

from propid.errors import UserError
from propid.flightlog import read_flightlog, read_vehicle
from propid.importers import import_log

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_importers import quad_vehicle, write_ulog  # noqa: E402 (after the path insert)

EXAMPLES = int(os.environ.get("PROPID_FUZZ_EXAMPLES", "40"))
FUZZ = settings(max_examples=EXAMPLES, derandomize=True, deadline=None, database=None,
                suppress_health_check=list(HealthCheck))
SHARED_BBL = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real" / "betaflight" / "btfl_004.bbl"

VEHICLE = {
    "name": "fuzz-quad", "mass": 0.6, "inertia": [3e-3, 3e-3, 5e-3],
    "rotors": [{"position": [0.08, -0.08, 0.0], "yaw_sign": -1}, {"position": [-0.08, 0.08, 0.0], "yaw_sign": -1},
               {"position": [0.08, 0.08, 0.0], "yaw_sign": 1}, {"position": [-0.08, -0.08, 0.0], "yaw_sign": 1}],
    "kf_nominal": 5e-6, "km_nominal": 1e-7, "rotor_inertia": 1e-6, "esc_delay_s": 0.001,
}


def csv_text(rows: int = 12) -> str:
    header = "t,gyro_x,gyro_y,gyro_z,omega_1,omega_2,omega_3,omega_4,acc_x,acc_y,acc_z"
    lines = [header]
    for k in range(rows):
        lines.append(",".join(f"{v:.6g}" for v in [k * 0.002, 0.01 * k, -0.02, 0.03, 1000 + k, 1001, 1002, 1003,
                                                   0.1, 0.0, 9.8]))
    return "\n".join(lines) + "\n"


def tlog_bytes() -> bytes:
    from propid import mavlink_io

    dialect = mavlink_io.dialect()
    mav = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = bytearray()
    for k in range(12):
        t = 2_000_000 + k * 2000
        imu = dialect.MAVLink_highres_imu_message(t, 0.5, -0.2, -9.7, 0.1, 0.2, 0.3, 0, 0, 0, 0, 0, 0, 0, 0)
        frames += struct.pack(">Q", 1_700_000_000_000_000 + t) + imu.pack(mav)
        if k % 2 == 0:
            esc = dialect.MAVLink_esc_status_message(0, t + 700, [15000, -16000, 17000, 18000], [12.0] * 4, [3.0] * 4)
            frames += struct.pack(">Q", 1_700_000_000_000_000 + t) + esc.pack(mav)
    return bytes(frames)


def ulog_bytes() -> bytes:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "f.ulg"
        write_ulog(path, 1000 + np.arange(12) * 4000, np.zeros((12, 3)), np.tile([0, 0, -9.8], (12, 1)),
                   1500 + np.arange(4) * 16000, np.full((4, 4), 12000))
        return path.read_bytes()


BBL_HEAD = b"H Product:Blackbox flight data recorder by Nicholas Sherlock\n"


def bbl_bytes() -> bytes:
    if SHARED_BBL.is_file():
        return SHARED_BBL.read_bytes()[:12000]  # read in memory only, never written into the repository
    return BBL_HEAD + b"H Data version:2\nH I interval:1\nH Field I name:loopIteration,time,gyroADC[0]\n"


# One mutation: (kind, position fraction, payload).
MUTATION = st.tuples(st.sampled_from(["flip", "insert", "delete", "truncate", "replace"]),
                     st.floats(0.0, 1.0), st.binary(min_size=1, max_size=16))


def mutate(data: bytes, mutations) -> bytes:
    out = bytearray(data)
    for kind, where, payload in mutations:
        at = int(where * len(out)) if out else 0
        if kind == "flip" and out:
            at = min(at, len(out) - 1)
            out[at] ^= payload[0] or 0xFF
        elif kind == "insert":
            out[at:at] = payload
        elif kind == "delete":
            del out[at:at + len(payload)]
        elif kind == "truncate":
            del out[at:]
        else:
            out[at:at + len(payload)] = payload
    return bytes(out)


def assert_one_line_or_ok(call) -> None:
    try:
        call()
    except UserError as exc:
        message = str(exc)
        assert message and "\n" not in message.strip(), f"UserError not one line: {message!r}"


def write(tmp_path: Path, name: str, data: bytes) -> Path:
    path = tmp_path / name
    path.write_bytes(data)
    return path


# Odd JSON values for vehicle fields.
ODD = st.one_of(st.none(), st.booleans(), st.integers(-10**30, 10**30), st.floats(allow_nan=True),
                st.text(max_size=8), st.lists(st.floats(allow_nan=True), max_size=5),
                st.lists(st.integers(-3, 3), max_size=5), st.dictionaries(st.text(max_size=4), st.integers(), max_size=2))


@FUZZ
@given(fields=st.dictionaries(st.sampled_from(sorted(VEHICLE) + ["rotors.0", "rotors.0.position", "rotors.1.yaw_sign",
                                                                   "gyro_scale", "aero_damping", "com_offset"]),
                              ODD, max_size=3),
       mutations=st.lists(MUTATION, max_size=2))
def test_vehicle_json_reader(tmp_path_factory, fields, mutations):
    data = json.loads(json.dumps(VEHICLE))
    for key, value in fields.items():
        parts = key.split(".")
        target = data
        try:
            for part in parts[:-1]:
                target = target[int(part)] if isinstance(target, list) else target[part]
            last = parts[-1]
            if isinstance(target, list):
                target[int(last)] = value
            else:
                target[last] = value
        except (KeyError, IndexError, TypeError, ValueError):
            pass
    text = json.dumps(data, allow_nan=True).encode()
    path = write(tmp_path_factory.mktemp("v"), "v.vehicle.json", mutate(text, mutations))
    assert_one_line_or_ok(lambda: read_vehicle(path))


CELL = st.one_of(st.sampled_from(["", "nan", "NaN", "inf", "-inf", "1e400", "-0", "x", " ", '"1"', "1,2", "0x10",
                                  "1e-320", "\t", "\x00"]),
                 st.floats(allow_nan=True).map(repr), st.integers().map(str), st.text(max_size=6))


@FUZZ
@given(cells=st.lists(st.tuples(st.integers(0, 12), st.integers(0, 10), CELL), max_size=4),
       header=st.lists(st.tuples(st.integers(0, 10), st.text(max_size=8)), max_size=2),
       mutations=st.lists(MUTATION, max_size=2))
def test_flightlog_csv_reader(tmp_path_factory, cells, header, mutations):
    rows = [line.split(",") for line in csv_text().splitlines()]
    for row, column, value in cells:
        rows[1 + row % (len(rows) - 1)][column] = value
    for column, name in header:
        rows[0][column] = name
    text = "\n".join(",".join(row) for row in rows).encode("utf-8", "surrogatepass")
    tmp = tmp_path_factory.mktemp("c")
    path = write(tmp, "f.csv", mutate(text, mutations))
    (tmp / "f.vehicle.json").write_text(json.dumps(VEHICLE))
    assert_one_line_or_ok(lambda: read_flightlog(path))
    assert_one_line_or_ok(lambda: import_log(path, "csv"))


def _importer_case(tmp_path_factory, name, fmt, data, mutations):
    path = write(tmp_path_factory.mktemp(fmt), name, mutate(data, mutations))
    assert_one_line_or_ok(lambda: import_log(path, fmt, quad_vehicle()))
    assert_one_line_or_ok(lambda: import_log(path, "auto", quad_vehicle()))


TLOG = tlog_bytes()
ULOG = ulog_bytes()
BBL = bbl_bytes()


@FUZZ
@given(mutations=st.lists(MUTATION, min_size=1, max_size=4))
def test_tlog_reader(tmp_path_factory, mutations):
    _importer_case(tmp_path_factory, "f.tlog", "tlog", TLOG, mutations)


@FUZZ
@given(mutations=st.lists(MUTATION, min_size=1, max_size=4))
def test_ulog_reader(tmp_path_factory, mutations):
    _importer_case(tmp_path_factory, "f.ulg", "ulog", ULOG, mutations)


@FUZZ
@given(mutations=st.lists(MUTATION, min_size=1, max_size=4))
def test_betaflight_reader(tmp_path_factory, mutations):
    _importer_case(tmp_path_factory, "f.bbl", "betaflight", BBL, mutations)


@FUZZ
@given(data=st.binary(max_size=300), magic=st.sampled_from([b"", BBL_HEAD, b"ULog\x01\x12\x35", bytes(8) + b"\xfd", b"t,"]))
def test_raw_bytes_behind_each_magic(tmp_path_factory, data, magic):
    for name, fmt in (("r.bin", "auto"), ("r.tlog", "tlog"), ("r.ulg", "ulog"), ("r.bbl", "betaflight"),
                      ("r.csv", "csv")):
        path = write(tmp_path_factory.mktemp("raw"), name, magic + data)
        assert_one_line_or_ok(lambda: import_log(path, fmt, quad_vehicle()))
    path = write(tmp_path_factory.mktemp("raw"), "r.vehicle.json", magic + data)
    assert_one_line_or_ok(lambda: read_vehicle(path))
