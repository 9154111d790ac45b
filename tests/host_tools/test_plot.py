"""propid.plotting and `propid plot`: PNGs from SITL-style CSVs and tlogs, and clean
errors on bad files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from propid import cli, mavlink_io, plotting
from propid.errors import UserError

ROTORS = 4


def sitl_like_csv(path: Path, seconds: float = 4.0, rate: float = 100.0) -> Path:
    """A CSV with the SITL log's column names: estimates converging to truth."""
    t = np.arange(0.0, seconds, 1.0 / rate)
    cols: dict[str, np.ndarray] = {"t": t}
    for a, phase in zip("xyz", (0.0, 1.0, 2.0)):
        cols[f"gyro_{a}"] = 0.5 * np.sin(3 * t + phase)
        cols[f"true_bg_{a}"] = np.full_like(t, 0.01 * (1 + phase))
        cols[f"est_bg_{a}"] = cols[f"true_bg_{a}"] * (1 - np.exp(-t))
        cols[f"std_bg_{a}"] = 0.02 * np.exp(-t) + 0.001
    for i in range(1, ROTORS + 1):
        cols[f"omega_{i}"] = 1500 + 100 * np.sin(5 * t + i)
        true_kf, true_km = 2.3e-8 * (1 + 0.05 * i), 7.8e-10 * (1 - 0.04 * i)
        cols[f"true_kf_{i}"] = np.full_like(t, true_kf)
        cols[f"true_km_{i}"] = np.full_like(t, true_km)
        cols[f"est_kf_{i}"] = 2.3e-8 + (true_kf - 2.3e-8) * (1 - np.exp(-2 * t))
        cols[f"std_kf_{i}"] = 0.2 * 2.3e-8 * np.exp(-2 * t) + 1e-10
        cols[f"est_km_{i}"] = 7.8e-10 + (true_km - 7.8e-10) * (1 - np.exp(-t))
        cols[f"std_km_{i}"] = 0.2 * 7.8e-10 * np.exp(-t) + 1e-12
    names = list(cols)
    with open(path, "w") as f:
        f.write(",".join(names) + "\n")
        for k in range(t.size):
            f.write(",".join(repr(float(cols[n][k])) for n in names) + "\n")
    return path


def tlog_with_telemetry(path: Path, steps: int = 60) -> Path:
    with mavlink_io.TlogWriter(path) as writer:
        seq = 0
        for k in range(steps):
            t_usec = 50_000 * k
            frames = [
                mavlink_io.encode_message(
                    "PROPID_COEFFICIENTS", sequence=seq, time_usec=t_usec,
                    thrust_coeff=[2.3e-8 * (1 + 0.001 * k)] * 4 + [0.0] * 4,
                    thrust_coeff_std=[1e-9 / (1 + k)] * 4 + [0.0] * 4,
                    drag_coeff=[7.8e-10] * 4 + [0.0] * 4,
                    drag_coeff_std=[3e-11 / (1 + k)] * 4 + [0.0] * 4,
                    thrust_coeff_converging=0, thrust_coeff_converged=0,
                    drag_coeff_converging=0, drag_coeff_converged=0, rotor_count=4),
                mavlink_io.encode_message(
                    "PROPID_GYRO", sequence=seq + 1, time_usec=t_usec,
                    gyro_bias=[0.01, 0.0, 0.0], gyro_bias_std=[0.005] * 3,
                    body_rate=[0.0] * 3, body_rate_std=[0.01] * 3, innovation=[0.0] * 3,
                    innovation_test_ratio=[0.0] * 3, health=0),
                mavlink_io.encode_message(
                    "ESC_STATUS", sequence=seq + 2, index=0, time_usec=t_usec,
                    rpm=[14000 + 10 * k, 14100, 14200, 14300], voltage=[0.0] * 4,
                    current=[0.0] * 4),
                mavlink_io.encode_message(
                    "HIGHRES_IMU", sequence=seq + 3, time_usec=t_usec, xacc=0.0, yacc=0.0,
                    zacc=-9.81, xgyro=0.1 * math.sin(k / 5), ygyro=0.2, zgyro=-0.3,
                    xmag=0.0, ymag=0.0, zmag=0.0, abs_pressure=0.0, diff_pressure=0.0,
                    pressure_alt=0.0, temperature=0.0, fields_updated=0x3F, id=0),
            ]
            seq += 4
            for frame in frames:
                writer.write(frame, 1_700_000_000.0 + 0.05 * k)
    return path


def assert_real_png(path: Path, min_bytes: int = 20_000) -> None:
    """Exists, is a PNG, is big enough, and is not a blank canvas."""
    import matplotlib.image as mpimg

    assert path.is_file()
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > min_bytes
    image = mpimg.imread(path)
    assert image.shape[0] > 500 and image.shape[1] > 500
    ink = np.mean(np.any(image[:, :, :3] < 0.9, axis=2))
    assert ink > 0.02, f"only {ink:.1%} of the image is drawn"


def test_plot_sitl_csv_with_truth(tmp_path):
    csv_path = sitl_like_csv(tmp_path / "flight.csv")
    flight = plotting.load_flight(csv_path)
    assert flight.rotor_count == ROTORS
    assert flight.truth is not None and flight.truth.has("true_kf_3")
    assert flight.estimates.has("std_km_4")
    out = plotting.plot_flight(flight, tmp_path / "flight.png")
    assert_real_png(out)


def test_plot_tlog_via_cli_with_truth_overlay(tmp_path):
    tlog = tlog_with_telemetry(tmp_path / "rec.tlog")
    truth = sitl_like_csv(tmp_path / "truth.csv")
    out = tmp_path / "rec.png"
    assert cli.main(["plot", "--log", str(tlog), "--truth", str(truth), "--out", str(out)]) == 0
    assert_real_png(out)
    flight = plotting.load_flight(tlog)
    assert flight.rotor_count == 4
    assert flight.estimates.t.size == 60
    # ESC rpm -> rad/s, HIGHRES_IMU FRD -> FLU
    assert flight.rotors.get("omega_2")[0] == pytest.approx(14100 * 2 * math.pi / 60)
    assert flight.rates.get("gyro_y")[0] == pytest.approx(-0.2)
    assert flight.rates.get("gyro_z")[0] == pytest.approx(0.3)


@pytest.mark.parametrize("content, message", [
    ("t,omega_1\n0,1\n1\n", "2 fields|1 fields"),
    ("t,omega_1\n0,1\n1,abc\n", "not a number"),
    ("time,omega_1\n0,1\n", "no 't' column"),
    ("t,omega_1\n", "header only"),
    ("t,gyro_x\n0,1\n", "nothing to plot"),
    ("t,omega_1\n1,1\n0,1\n", "decreases"),
])
def test_bad_csv_files_are_user_errors(tmp_path, content, message):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    with pytest.raises(UserError, match=message):
        plotting.load_flight(path)


def test_binary_and_unknown_files_are_user_errors(tmp_path):
    binary = tmp_path / "bin.csv"
    binary.write_bytes(bytes(range(256)) * 10)
    with pytest.raises(UserError):
        plotting.load_flight(binary)
    other = tmp_path / "flight.ulg"
    other.write_bytes(b"x")
    with pytest.raises(UserError, match="unknown log type"):
        plotting.load_flight(other)
    with pytest.raises(UserError, match="no such file"):
        plotting.load_flight(tmp_path / "absent.csv")


def test_truncated_csv_is_a_user_error_with_line(tmp_path):
    full = sitl_like_csv(tmp_path / "full.csv", seconds=1.0)
    data = full.read_text()
    cut = tmp_path / "cut.csv"
    cut.write_text(data[: len(data) - 200])
    with pytest.raises(UserError, match=r"cut\.csv line \d+"):
        plotting.load_flight(cut)


def test_plot_rejects_non_png_output(tmp_path, capsys):
    csv_path = sitl_like_csv(tmp_path / "f.csv", seconds=0.5)
    assert cli.main(["plot", "--log", str(csv_path), "--out", str(tmp_path / "f.jpg")]) == 1
    assert "PNG" in capsys.readouterr().err
