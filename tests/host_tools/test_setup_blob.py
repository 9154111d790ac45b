"""The host generator of a vehicle's prepared setup (firmware/codegen/setup_blob.py):
it writes the firmware's own derivation as C bytes sealed with zlib's CRC-32, and
refuses a vehicle file the firmware would refuse, in one line. (That the bytes
start the same filter as propid_init is tests/firmware/prepared_vehicle_check.c.)"""

from __future__ import annotations

import json
import pathlib
import re
import subprocess
import sys
import zlib

REPO = pathlib.Path(__file__).resolve().parents[2]
GENERATOR = REPO / "firmware" / "codegen" / "setup_blob.py"
VEHICLE = json.loads((REPO / "tests" / "bench" / "footprint_vehicle.json").read_text())


def generate(tmp_path: pathlib.Path, vehicle, *args: str) -> subprocess.CompletedProcess:
    source = tmp_path / "vehicle.json"
    source.write_text(vehicle if isinstance(vehicle, str) else json.dumps(vehicle))
    return subprocess.run([sys.executable, str(GENERATOR), str(source), "--out", str(tmp_path / "setup.c"), *args],
                          capture_output=True, text=True)


def test_setup_bytes_are_sealed_with_zlib_crc32(tmp_path):
    result = generate(tmp_path, VEHICLE)
    assert result.returncode == 0, result.stderr
    text = (tmp_path / "setup.c").read_text()
    blob = bytes(int(b, 16) for b in re.findall(r"0x([0-9a-f]{2})\b", text.split("setup_bytes = {", 1)[1]))
    size = int(re.search(r"sizeof\(propid_setup_t\) == (\d+)u", text).group(1))
    checksum_at = int(re.search(r"offsetof\(propid_setup_t, checksum\) == (\d+)u", text).group(1))
    assert len(blob) == size
    assert int.from_bytes(blob[checksum_at:checksum_at + 4], "little") == zlib.crc32(blob[:checksum_at])
    # format: "PS", the version, this build's rotor count and options (propid.h)
    assert blob[2:4] == b"SP" and blob[1] == 1 and blob[0] == 0x04
    assert int.from_bytes(blob[4:8], "little") == size
    # a field of the file reaches the bytes: another gate, another setup
    other = generate(tmp_path, {**VEHICLE, "gate_sigma": 3.0})
    assert other.returncode == 0, other.stderr
    assert (tmp_path / "setup.c").read_text() != text


def test_bad_vehicle_files_are_refused_in_one_line(tmp_path):
    cases = [
        ({**VEHICLE, "gate_sigma": 0.5}, "configuration rejected: gate_sigma"),
        ({**VEHICLE, "inertia_diag": [3.65e-3, -1.0, 7.03e-3]}, "configuration rejected: inertia"),
        ({**VEHICLE, "gate_sigmaa": 4.0}, "unknown field 'gate_sigmaa'"),
        ({**VEHICLE, "gate_max_consecutive": 1.5}, "gate_max_consecutive: not an integer"),
        ({**VEHICLE, "rotors": {**VEHICLE["rotors"], "count": 6}}, "configuration rejected: rotors"),
        ({k: v for k, v in VEHICLE.items() if k != "inertia_diag"}, "inertia"),
        ("{not json", "cannot read a vehicle"),
    ]
    for vehicle, reason in cases:
        result = generate(tmp_path, vehicle)
        assert result.returncode == 1, (vehicle, result.stdout)
        assert reason in result.stderr, result.stderr
        assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr


def test_help():
    result = subprocess.run([sys.executable, str(GENERATOR), "--help"], capture_output=True, text=True)
    assert result.returncode == 0 and "propid_init_prepared" in result.stdout
