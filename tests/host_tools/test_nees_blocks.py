"""tests/soak/nees_blocks.py: the NEES of a --nees-dump per block, per information direction, and
the loading's fading memory (docs/reliability.md, "Why the exact-speed flights are underconfident")."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

TOOL = Path(__file__).resolve().parents[1] / "soak" / "nees_blocks.py"
EPS = 2.0 ** -23


def write_dump(path: Path, times, errors, covariances, rotors: int = 4) -> None:
    """A file in propid_sitl's --nees-dump format with identity bases."""
    n = 2 * rotors + 3
    lines = [f"# propid_sitl NEES samples: {rotors} rotors, {n} states"]
    for name in ("kf", "km"):
        for k in range(rotors):
            lines.append(f"# {name}_basis_{k}," + ",".join("1" if j == k else "0" for j in range(rotors)))
    rows, cols = np.tril_indices(n)
    lines.append("t,nees," + ",".join(f"e_{i}" for i in range(n))
                 + "," + ",".join(f"p_{i}_{j}" for i, j in zip(rows, cols)))
    for t, e, p in zip(times, errors, covariances):
        nees = float(e @ np.linalg.solve(p, e))
        values = [t, nees, *e, *p[rows, cols]]
        lines.append(",".join(f"{v:.17g}" for v in values))
    path.write_text("\n".join(lines) + "\n")


def test_blocks_and_directions_of_a_known_covariance(tmp_path, soak_script):
    """Diagonal P with kf at 1e-6, km at 1e-2 and the biases at 1 of their prior variance, errors at
    0.5, 1 and sqrt(2) std: block NEES/dof 0.25 / 1 / 2, the same per direction bin, the sample
    before --from left out, and the fading of the best-determined (kf) directions eps per step."""
    tool = soak_script("nees_blocks")
    prior = np.array([tool.PRIOR_COEFF_STD] * 8 + [tool.PRIOR_BIAS_STD] * 3)
    variance = prior ** 2 * np.array([1e-6] * 4 + [1e-2] * 4 + [1.0] * 3)
    z = np.array([0.5] * 4 + [1.0] * 4 + [np.sqrt(2.0)] * 3)
    times = [0.1, 0.6, 1.0, 1.4]
    errors = [z * np.sqrt(variance) * (50.0 if t < 0.5 else (-1.0) ** k) for k, t in enumerate(times)]
    dump = tmp_path / "nees.csv"
    write_dump(dump, times, errors, [np.diag(variance)] * len(times))
    result = tool.analyse(str(dump), t_from=0.5, gyro_rate_hz=500.0)
    assert result["samples"] == 3 and result["dof"] == 11
    assert result["block_nees_per_dof"] == pytest.approx({"kf": 0.25, "km": 1.0, "bias": 2.0}, rel=1e-6)
    assert result["nees_per_dof"] == pytest.approx((4 * 0.25 + 4 * 1.0 + 3 * 2.0) / 11, rel=1e-4)
    bins = {tuple(b["eigenvalue_over_prior"]): (b["mean_z_squared"], b["directions_per_sample"])
            for b in result["directions"]}
    assert bins == {(0.0, 1e-5): (0.25, 4.0), (1e-2, 1e-1): (1.0, 4.0), (1e-1, None): (2.0, 3.0)}
    assert result["fading_per_s"] == pytest.approx([EPS * 500.0] * 3, rel=1e-6)
    halves = tool.analyse(str(dump), t_from=0.5, windows=2)["over_time"]
    assert [(h["from_s"], h["to_s"]) for h in halves] == [(0.6, 1.0), (1.0, 1.4)]
    assert [h["kf"] for h in halves] == pytest.approx([0.25, 0.25], rel=1e-6)


def test_fading_of_a_combination_held_by_larger_variances(tmp_path, soak_script):
    """Two thrust coefficients of variance 1e-4 correlated to 1 - 1e-6: their difference has a
    variance of 1e-10 per unit direction, and eps x 1e-4 on each diagonal loads it by eps x 1e6
    per step, 500 x that per second at 500 Hz (the cost the exact-speed hexa and octo flights pay)."""
    tool = soak_script("nees_blocks")
    cov = np.diag([1e-4] * 8 + [1e-6] * 3)
    cov[0, 1] = cov[1, 0] = 1e-4 * (1.0 - 1e-6)
    dump = tmp_path / "nees.csv"
    write_dump(dump, [1.0, 2.0], [np.full(11, 1e-6), np.full(11, -1e-6)], [cov, cov])
    fading = tool.analyse(str(dump), gyro_rate_hz=500.0)["fading_per_s"]
    assert fading[0] == pytest.approx(EPS * 1e6 * 500.0, rel=1e-3)
    assert fading[1] == pytest.approx(EPS * 500.0, rel=1e-3)


def test_a_sitl_dump_reads_back_the_flight_nees(sitl_binary, tmp_path):
    """A short exact-speed flight's dump: the tool's NEES per dof over all samples is the summary's
    mean NEES per dof, and the three blocks are finite and positive."""
    dump, summary, out = tmp_path / "nees.csv", tmp_path / "flight.json", tmp_path / "blocks.json"
    subprocess.run([str(sitl_binary), "--vehicle", "crazyflie-x", "--trajectory", "circle", "--duration", "3",
                    "--paper", "--quiet", "--summary-json", str(summary), "--nees-dump", str(dump)],
                   check=True, capture_output=True)
    proc = subprocess.run([sys.executable, str(TOOL), str(dump), "--from", "0", "--out", str(out)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(out.read_text())[0]
    honesty = json.loads(summary.read_text())["honesty"]
    assert result["samples"] == honesty["nees_samples"]
    assert result["nees_per_dof"] == pytest.approx(honesty["nees_mean"] / honesty["nees_dof"], rel=1e-3)
    assert all(np.isfinite(v) and v > 0.0 for v in result["block_nees_per_dof"].values())
    assert "NEES/dof" in proc.stdout


def test_a_file_that_is_not_a_dump_gets_one_line(tmp_path):
    bad = tmp_path / "flight.csv"
    bad.write_text("t,gyro_x\n0,1\n")
    proc = subprocess.run([sys.executable, str(TOOL), str(bad)], capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "not a propid_sitl --nees-dump file" in proc.stderr
    assert "Traceback" not in proc.stderr
