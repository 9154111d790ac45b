"""One reader per format: the plot and the importer see the same tlog samples, the
filter configuration comes from the parsed Vehicle, unit conversions live in one place,
and the replay keeps no module-level cache of the C library."""

from __future__ import annotations

import ast
import io
import re
import struct
import tokenize
from pathlib import Path

import numpy as np
import pytest

from propid import mavlink_io, plotting
from propid.cfilter import FilterConfig
from propid.errors import UserError
from propid.flightlog import parse_vehicle
from propid.importers.tlog import import_tlog

PACKAGE = Path(__file__).resolve().parents[2] / "host_tools" / "propid"
VEHICLE = {
    "name": "quad",
    "inertia": [1e-3, 1e-3, 2e-3],
    "rotors": [{"position": [0.1 * x, 0.1 * y, 0.0], "yaw_sign": s}
               for x, y, s in ((1, -1, -1), (-1, -1, 1), (-1, 1, -1), (1, 1, 1))],
    "kf_nominal": 2e-8,
    "km_nominal": [5e-10, 5e-10, 5e-10, 5e-10],
}


def _tlog(path: Path) -> Path:
    """HIGHRES_IMU at 500 Hz; ESC_STATUS at 125 Hz with one negative rpm (spin direction)
    and, every 10th sample, a stopped rotor 4."""
    dialect = mavlink_io.dialect()
    mav = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = bytearray()
    for k in range(100):
        t = 1_000_000 + k * 2000
        imu = dialect.MAVLink_highres_imu_message(t, 0.0, 0.0, -9.8, 0.1, 0.2, 0.3, 0, 0, 0, 0, 0, 0, 0, 0)
        frames += struct.pack(">Q", 1_700_000_000_000_000 + t) + imu.pack(mav)
        if k % 4 == 0:
            rpm = [10000 + k, -11000 - k, 12000, 13000 if k % 40 else 0]
            esc = dialect.MAVLink_esc_status_message(0, t + 300, rpm, [0.0] * 4, [0.0] * 4)
            frames += struct.pack(">Q", 1_700_000_000_000_000 + t) + esc.pack(mav)
    path.write_bytes(bytes(frames))
    return path


def test_plot_and_importer_read_the_same_tlog_samples(tmp_path):
    path = _tlog(tmp_path / "f.tlog")
    log, _ = import_tlog(path, parse_vehicle(VEHICLE))
    rows = np.all(np.isfinite(log.rotor_speed), axis=1)
    flight = plotting.load_flight(path)
    plotted = np.column_stack([flight.rotors.get(f"omega_{i}") for i in range(1, 5)])
    np.testing.assert_array_equal(plotted, log.rotor_speed[rows])
    np.testing.assert_allclose(np.diff(flight.rotors.t), np.diff(log.t[rows]), atol=1e-9)
    assert np.all(plotted >= 0)  # magnitudes, whatever the ESC's sign convention


def test_filter_configuration_comes_from_the_parsed_vehicle():
    config = FilterConfig.from_vehicle(parse_vehicle(VEHICLE))
    assert config.thrust_coeff_nominal == [2e-8] * 4 and config.inertia[2][2] == 2e-3
    with pytest.raises(UserError, match="inertia"):
        FilterConfig.from_vehicle(parse_vehicle({**VEHICLE, "inertia": None}))


def _code_only(path: Path) -> str:
    """The source without strings and comments (messages may mention 2*pi/60)."""
    tokens = tokenize.generate_tokens(io.StringIO(path.read_text(encoding="utf-8")).readline)
    return " ".join(t.string for t in tokens if t.type not in (tokenize.STRING, tokenize.COMMENT))


def test_unit_conversions_live_in_units_only():
    factor = re.compile(r"pi\s*/\s*(60|30)\b|/\s*60\.0")
    offenders = [str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*.py")
                 if p.name != "units.py" and factor.search(_code_only(p))]
    assert offenders == []


def test_replay_keeps_no_module_level_mutable_state():
    for path in (PACKAGE / "replay").glob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in tree.body:
            if isinstance(node, (ast.Assign, ast.AnnAssign)):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                if all(isinstance(t, ast.Name) and t.id.startswith("__") for t in targets):
                    continue  # __all__
                value = node.value
                assert not isinstance(value, (ast.Dict, ast.List, ast.Set)), f"{path.name}: module-level {ast.dump(node)[:80]}"
