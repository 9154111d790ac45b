"""Several replays of one vehicle: fleet statistics and the per-run validation table."""

from __future__ import annotations

from pathlib import Path

import numpy as np

# ----------------------------------------------------------------------------- fleet validation
def _cv(values: list[float]) -> float:
    arr = np.asarray(values, dtype=float)
    return float(np.std(arr, ddof=1) / np.mean(arr)) if arr.size > 1 and np.mean(arr) != 0 else float("nan")


def fleet_summary(summaries: list[dict], reference_kf: float | None = None) -> dict:
    """Statistics over several replays of one vehicle: mean of the per-run means (over
    rotors), their coefficient of variation (std/mean, ddof 1), agreement with the
    independent kf, and the same for the least-squares checks when they were run."""
    kf_runs = [float(np.mean(s["kf_mean"])) for s in summaries]
    km_runs = [float(np.mean(s["km_mean"])) for s in summaries]
    out = {
        "runs": len(summaries),
        "kf_fleet_mean": float(np.mean(kf_runs)),
        "kf_run_cv": _cv(kf_runs),
        "km_fleet_mean": float(np.mean(km_runs)),
        "km_run_cv": _cv(km_runs),
        "all_finite": all(s["finite"] for s in summaries),
        "kf_converged_runs": sum(all(s["converged"]["kf"]) for s in summaries),
        "runs_with_state_clamps": sum(1 for s in summaries if s["counters"].get("state_clamps", 0) > 0),
        "cov_repairs": sum(s["counters"].get("cov_repairs", 0) for s in summaries),
        "km_converged_runs": sum(all(s["converged"]["km"]) for s in summaries),
    }
    if reference_kf:
        out["reference_kf"] = reference_kf
        out["kf_fleet_over_reference"] = out["kf_fleet_mean"] / reference_kf
    checks = [s.get("checks") for s in summaries]
    if all(c and c.get("bands") for c in checks):
        def pooled(band, key, coeff):
            vals = [c["bands"][band][key][coeff] for c in checks if band in c["bands"] and key in c["bands"][band]]
            return {"mean": float(np.mean(vals)), "cv": _cv(vals)} if vals else None

        out["checks"] = {
            "thrust_kf_raw": pooled("raw", "thrust_kf", "kf"),
            "roll_kf_raw": pooled("raw", "roll_kf", "kf"),
            "pitch_kf_raw": pooled("raw", "pitch_kf", "kf"),
            "roll_kf_raw_with_velocity": pooled("raw", "roll_kf_with_velocity", "kf"),
            "pitch_kf_raw_with_velocity": pooled("raw", "pitch_kf_with_velocity", "kf"),
            "roll_kf_2_10Hz": pooled("2-10Hz", "roll_kf", "kf"),
            "pitch_kf_2_10Hz": pooled("2-10Hz", "pitch_kf", "kf"),
            "yaw_km_2_10Hz_with_rotor_inertia": pooled("2-10Hz", "yaw_km_rotor_inertia", "km"),
        }
    return out


def validation_table(summaries: list[dict], reference_kf: float | None = None) -> str:
    """Markdown table, one row per run (the docs' validation table)."""
    ref = reference_kf or float("nan")
    head = ("| run | s | ESC delay [ms] | rotor samples rejected | gated gyro axes | clamped steps | filter kf (x ref) | kf rotor spread | filter km | km conv. "
            "| acc thrust kf | LS roll/pitch kf raw | raw + velocity moment | 2-10 Hz | 2-10 Hz km |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for s in summaries:
        kf = np.asarray(s["kf_mean"])
        name = Path(s["log"]).stem if s.get("log") else "?"
        rejected = sum(v for k, v in s["rejected"].items() if k in ("PROPID_ERR_NOT_FINITE", "PROPID_ERR_ROTOR_SPEED_RANGE"))
        c = (s.get("checks") or {}).get("bands", {})

        def fit(band, key, coeff="kf", fmt="{:.2f}"):
            try:
                return fmt.format(c[band][key][coeff] / ref) if coeff == "kf" else fmt.format(c[band][key][coeff])
            except KeyError:
                return "n/a"

        lines.append(
            f"| {name} | {s['duration_s']:.0f} | {1e3 * s.get('esc_delay_s', -s.get('rotor_delay_s', 0.0)):.0f} | {rejected} | "
            f"{sum(s['counters'].get('axis_gated', [0]))} | {s['counters'].get('state_clamps', 0)} | "
            f"{kf.mean():.3g} ({kf.mean() / ref:.2f}) | "
            f"{_cv(kf):.0%} | {np.mean(s['km_mean']):.3g} | {sum(s['converged']['km'])}/{len(kf)} | "
            f"{fit('raw', 'thrust_kf')} | {fit('raw', 'roll_kf')}/{fit('raw', 'pitch_kf')} | "
            f"{fit('raw', 'roll_kf_with_velocity')}/{fit('raw', 'pitch_kf_with_velocity')} | "
            f"{fit('2-10Hz', 'roll_kf')}/{fit('2-10Hz', 'pitch_kf')} | "
            f"{fit('2-10Hz', 'yaw_km_rotor_inertia', 'km', '{:.2g}')} |"
        )
    return "\n".join(lines)

