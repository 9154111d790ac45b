"""DIR/index.html: a self-contained report read top to bottom (verdict, base fit,
where, each effect's evidence, before/after), PNG plots beside it."""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_base_fit(result: dict, path: Path) -> None:
    plt = _plt()
    keys = ["kf_thrust", "kf_roll", "kf_pitch"]
    fig, ax = plt.subplots(figsize=(6, 3), dpi=80)
    for k, (tag, shape) in enumerate((("before", result["base_fit"]), ("after", result["base_fit_after"]))):
        xs, vs, lo, hi = [], [], [], []
        for j, key in enumerate(keys):
            e = shape.get(key)
            if e:
                xs.append(j + (k - 0.5) * 0.3)
                vs.append(e["value"])
                lo.append(e["value"] - e["ci"][0])
                hi.append(e["ci"][1] - e["value"])
        if xs:
            ax.errorbar(xs, vs, yerr=[lo, hi], fmt="o", capsize=3, label=tag)
    ax.set_xticks(range(len(keys)))
    ax.set_xticklabels(keys)
    ax.set_ylabel("kf [N/(rad/s)^2]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_where(result: dict, path: Path) -> None:
    plt = _plt()
    where = result["where"]
    fig, axes = plt.subplots(1, 2, figsize=(9, 3), dpi=80)
    bands = list(where["per_band"])
    for a in ("roll", "pitch", "yaw"):
        axes[0].plot(range(len(bands)), [where["per_band"][b][a] for b in bands], "-o", ms=3, label=a)
    axes[0].set_xticks(range(len(bands)))
    axes[0].set_xticklabels(bands, fontsize=7)
    axes[0].set_ylabel("residual / response RMS")
    axes[0].set_title("base-model residual per band", fontsize=9)
    axes[0].legend(fontsize=7)
    axes[0].grid(alpha=0.3)
    regimes = [r for r, v in where["per_regime"].items() if v.get("roll") is not None]
    width = 0.25
    for k, a in enumerate(("roll", "pitch", "yaw")):
        sigma = where["per_axis"][a]["residual_rms"] or 1
        axes[1].bar(np.arange(len(regimes)) + (k - 1) * width,
                    [where["per_regime"][r][a] / sigma for r in regimes], width, label=a)
    axes[1].set_xticks(range(len(regimes)))
    axes[1].set_xticklabels(regimes, fontsize=7, rotation=15)
    axes[1].set_title("residual RMS per regime / overall", fontsize=9)
    axes[1].grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def interval_centre(entry: dict):
    """The value an entry's `ci` is an interval of: the block-weighted held-out fraction where the
    entry has a held-out replication test (its p-value's statistic), else the explained fraction."""
    return entry.get("held_out_weighted_fraction", entry.get("explained_fraction"))


def plot_effects(result: dict, path: Path) -> None:
    plt = _plt()
    effects = result["effects"]
    fig, ax = plt.subplots(figsize=(7, 0.3 * len(effects) + 1), dpi=80)
    y = np.arange(len(effects))[::-1]

    def reach(e, k):  # an interval that is undefined (null: e.g. no held-out block) draws no bar
        v, lo_hi = interval_centre(e), e.get("ci") or [None, None]
        if v is None or lo_hi[k] is None:
            return 0.0
        return abs(v - lo_hi[k])

    vals = [interval_centre(e) or 0.0 for e in effects]
    err = [[reach(e, 0) for e in effects], [reach(e, 1) for e in effects]]
    colors = ["C3" if e["significant"] else "C7" for e in effects]
    ax.barh(y, vals, xerr=err, color=colors, capsize=2)
    ax.set_yticks(y)
    ax.set_yticklabels([e["id"] for e in effects], fontsize=8)
    ax.set_xlabel("held-out explained fraction, block-weighted where tested, with its 95 % interval "
                  "(red: significant)", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_shrink(result: dict, path: Path) -> None:
    plt = _plt()
    shrink = result["shrink"]
    axes_ = list(shrink)
    fig, ax = plt.subplots(figsize=(6, 3), dpi=80)
    before = [1.0 for _ in axes_]
    after = [shrink[a]["rms_after"] / shrink[a]["rms_before"] if shrink[a]["rms_before"] else 0 for a in axes_]
    ax.bar(np.arange(len(axes_)) - 0.2, before, 0.4, label="base model")
    ax.bar(np.arange(len(axes_)) + 0.2, after, 0.4, label="with significant effects")
    ax.set_xticks(range(len(axes_)))
    ax.set_xticklabels(axes_)
    ax.set_ylabel("held-out residual RMS (relative)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_alignment(result: dict, path: Path) -> None:
    plt = _plt()
    curve = result["alignment"]["sse_curve"]
    fig, ax = plt.subplots(figsize=(6, 2.6), dpi=80)
    ax.plot(np.array(curve["delay_s"]) * 1e3, curve["weighted_sse"], "-")
    ax.axvline(result["alignment"]["delay_s"] * 1e3, color="C3", ls="--")
    ax.set_xlabel("rotor stream shifted by [ms] (positive: telemetry lags)")
    ax.set_ylabel("roll/pitch residual (rel. to 0)")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _fmt(v) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    if isinstance(v, dict):
        return ", ".join(f"{k} {_fmt(x)}" for k, x in v.items())
    return html.escape(str(v))


def _table(head: list[str], rows: list[list]) -> str:
    out = ["<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr>"]
    for r in rows:
        out.append("<tr>" + "".join(f"<td>{_fmt(c)}</td>" for c in r) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def _explainable_section(result: dict) -> str:
    """How much of the held-out residual is predictable at all (gap/explainable.py)."""
    ex = result.get("explainable")
    if not ex:
        return ""
    if not ex.get("computed"):
        return f"<h3>Predictable at all</h3><p>not computed: {html.escape(str(ex.get('why')))}</p>"
    from propid.gap.explainable import report_line
    lines = [report_line(a, v, result["shrink"].get(a, {}).get("reduction")) for a, v in ex.items()
             if a in ("roll", "pitch", "yaw")]
    rows = [[a, v["explainable_fraction"], v["explainable_rms_shrink"], v["inputs_fraction"], v["motion_fraction"],
             v.get("gyro_noise_power_share"), v.get("named_effects_share")]
            for a, v in ex.items() if a in ("roll", "pitch", "yaw")]
    return ("<h3>Predictable at all</h3><p>" + html.escape(ex["how"]) + "</p><ul>"
            + "".join(f"<li>{html.escape(t)}</li>" for t in lines) + "</ul>"
            + _table(["axis", "explainable (power)", "as RMS shrink", "inputs only", "motion (attitude, all taps)",
                      "gyro noise share", "named effects' share"], rows))


def write_report(result: dict, directory: str | Path) -> Path:
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    plots = {"base_fit.png": plot_base_fit, "where.png": plot_where, "effects.png": plot_effects,
             "shrink.png": plot_shrink, "alignment.png": plot_alignment}
    for name, fn in plots.items():
        fn(result, d / name)
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>propid gap report</title>",
             "<style>body{font-family:sans-serif;max-width:1000px;margin:2em auto}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:2px 6px;font-size:13px}</style></head><body>",
             "<h1>propid gap: sim-to-real gap diagnosis</h1>",
             f"<h2>Verdict: {html.escape(result['verdict'])}</h2>",
             f"<p>Significant effects: {_fmt(result['significant']) or 'none'}. Logs: {_fmt(result['inputs']['logs'])}; "
             f"hold-out: {_fmt(result['inputs']['holdout']) or 'none (cross-validation)'}; vehicle "
             f"{_fmt(result['inputs']['vehicle'])}; band {_fmt(result['inputs']['band_hz'])} Hz.</p>"]
    if result["ambiguous"]:
        parts.append("<p><b>Ambiguous</b>: " + "; ".join(
            f"{_fmt(a['candidates'])} ({html.escape(a['reason'])})" for a in result["ambiguous"]) + "</p>")
    if result["untestable"]:
        parts.append("<p><b>Untestable</b> (missing inputs): " + "; ".join(
            f"{u['id']} ({', '.join(u['missing'])})" for u in result["untestable"]) + "</p>")
    repeated = (result.get("stream_quality") or {}).get("repeated_rows")
    if repeated:
        how = ("missing samples in the fits (torque and Omega^2 interpolated across them)"
               if repeated["treated_as"] == "missing" else "samples in the fits")
        parts.append("<h2>Stream quality: repeated rows</h2><p>Rows repeating the previous row's gyro triple or "
                     "rotor speeds bit for bit (a logger's copies of lost packets) among the flying rows analysed; "
                     f"treated as {how}; the firmware-filter check skips them. Logs above 5 %: {_fmt(repeated['logs_above_5_percent']) or 'none'}.</p>")
        parts.append(_table(["log", "role", "gyro share", "gyro longest run", "rotor share", "rotor longest run"],
                            [[name, v["role"], v["gyro"]["share"], v["gyro"]["longest_run"], v["rotor"]["share"],
                              v["rotor"]["longest_run"]] for name, v in repeated["per_log"].items()]))
    parts.append("<h2>Base fit</h2><p>Fleet coefficients with 95 % block-bootstrap intervals; thrust from the "
                 "accelerometer, roll/pitch/yaw from the gyro torques; after = with the significant effects in.</p>")
    rows = []
    for key in ("kf_thrust", "kf_roll", "kf_pitch", "km_yaw"):
        b, a = result["base_fit"].get(key), result["base_fit_after"].get(key)
        det = result["base_fit_details"]["before"].get(key) or {}
        rows.append([key, b and b["value"], b and b["ci"], a and a["value"], a and a["ci"], det.get("method")])
    parts.append(_table(["quantity", "before", "95 % CI", "after", "95 % CI", "method"], rows))
    parts.append(f"<p>Agreement with the thrust kf: before {_fmt(result['base_fit_details']['agreement_before'])}; "
                 f"after {_fmt(result['base_fit_details']['agreement_after'])}.</p>")
    parts.append(f"<p>{html.escape(result['base_fit_method'])}.</p>")
    offset = result["base_fit_details"].get("thrust_offset") or {}
    if offset.get("before"):  # --thrust-offset segment: the accelerometer's z offset per log
        before = offset["before"]
        parts.append("<p>Thrust axis with a constant per segment (the accelerometer's zero-g offset): collective "
                     f"thrust variation {_fmt(before['collective_variation'])}, kf_thrust interval half-width "
                     f"{_fmt(before['kf_thrust_ci_relative_halfwidth'])} of its value "
                     f"({'determined' if before['determined'] else 'not determined: the offset and kf are not told apart'}"
                     ").</p>")
        parts.append(_table(["log", "offset [m/s^2]", "95 % CI"],
                            [[name, v["m_s2"], v["ci"]] for name, v in before["per_log"].items()]))
    loop = next((e for e in result["effects"] if e["id"] == "closed_loop_cancellation" and e["significant"]), None)
    if loop is not None:
        p = loop["params"]
        parts.append(f"<p><b>Closed-loop cancellation</b>: the roll/pitch torque kf of the band from "
                     f"{_fmt(p['requested_highpass_hz'])} Hz is {_fmt(p['torque_gain_below'])}x the kf above "
                     f"{_fmt(p['loop_bandwidth_hz'])} Hz (95 % {_fmt(p['torque_gain_below_ci'])}): the controller "
                     f"cancels a slow torque ({_fmt(p['disturbance_torque_rms'])} N m rms below that edge) with its "
                     f"rotors, which the gyro never sees. Before = from {_fmt(p['requested_highpass_hz'])} Hz; "
                     f"after and every effect: above {_fmt(p['loop_bandwidth_hz'])} Hz.</p>")
    parts.append("<img src='base_fit.png'>")
    gain = result["base_fit_details"].get("torque_gain_per_band")
    if gain:
        rel = "over_thrust" in gain["roll"][0]
        parts.append(f"<p><b>Torque gain per band</b> ({html.escape(gain['method'])}; "
                     f"{'over the thrust kf' if rel else 'kf'}, phase in degrees): equal in every band when the "
                     "rotors follow a reference; rising with frequency (low, then above the truth where a lagged "
                     "loop amplifies it) when the loop answers an unmodelled torque, and then no band edge reads "
                     "the truth.</p>")
        key = "over_thrust" if rel else "value"
        parts.append(_table(["band [Hz]", "roll", "roll phase", "pitch", "pitch phase"],
                            [[r["band_hz"], r[key], r["phase_deg"], q[key], q["phase_deg"]]
                             for r, q in zip(gain["roll"], gain["pitch"])]))
    parts.append("<h2>Where the base model misses</h2>")
    w = result["where"]
    parts.append(_table(["axis", "residual RMS", "response RMS", "unexplained fraction"],
                        [[a, v["residual_rms"], v["response_rms"], v["unexplained_fraction"]]
                         for a, v in w["per_axis"].items()]))
    parts.append(_table(["regime", "share of rows"] + list(w["per_axis"]),
                        [[r, v["fraction_of_rows"]] + [v.get(a) for a in w["per_axis"]] for r, v in w["per_regime"].items()]))
    parts.append(_table(["band", "roll", "pitch", "yaw"], [[b, v["roll"], v["pitch"], v["yaw"]] for b, v in w["per_band"].items()]))
    thrust = w.get("thrust_gain_per_band")
    if thrust:
        demeaned = thrust["segment_demeaned"]
        parts.append(f"<p><b>Thrust gain per band</b> (m acc_z against sum Omega_i^2, each over the static kf "
                     f"{_fmt(thrust['static_kf'])} through the origin): h1 least squares (low when the rotor speeds are "
                     "noisy), h2 reverse regression (high when the accelerometer is), coherence = h1 / h2, instrument "
                     "= the motor commands' prediction of the collective. One gain: h1 ~ h2 ~ instrument and coherence "
                     f"near 1. Segment means removed (the slope --thrust-offset segment fits): h1 {_fmt(demeaned['h1'])}, "
                     f"h2 {_fmt(demeaned['h2'])}, coherence {_fmt(demeaned['coherence'])}.</p>")
        parts.append(_table(["band", "h1", "h2", "coherence", "instrument"],
                            [[b, v["h1"], v["h2"], v["coherence"], v["instrument"]]
                             for b, v in thrust["per_band"].items()]))
    parts.append(f"<p>Per rotor (relative to the fleet mean): kf {_fmt(w['per_rotor']['kf_relative'])}, "
                 f"km {_fmt(w['per_rotor']['km_relative'])}.</p><img src='where.png'>")
    parts.append("<h2>Which effects</h2><p>Held-out explained fraction of the current residual (unweighted: "
                 "the ranking's); the held-out replication's statistic, each second weighted by the inverse of "
                 "its residual power, with its two-sided 95 % interval (it excludes 0 exactly when the two-sided "
                 "p is below 5 %) and the one-sided held-out p-value; where an entry has no held-out test (the "
                 "raw-row lag, closed-loop cancellation) the interval is its block-bootstrap interval of the "
                 "explained fraction. Effect size: RMS of its own contribution / response variation.</p>")
    parts.append(_table(["effect", "explained", "weighted", "95 % CI (of the weighted where given)", "held-out p",
                         "effect size", "axes", "significant", "parameters"],
                        [[e["id"], e["explained_fraction"], e.get("held_out_weighted_fraction"), e["ci"],
                          e.get("held_out_p_value"), e.get("effect_size"), e["axes"], str(e["significant"]),
                          e["params"]] for e in result["effects"]]))
    parts.append("<img src='effects.png'><h3>Stream alignment (esc_delay)</h3><img src='alignment.png'>")
    parts.append(f"<h2>How far ({html.escape(result['shrink_on'])})</h2>")
    parts.append("<p>Library floor: the RMS the base model plus every testable candidate leaves on the same rows, "
                 "fitted in-sample; no choice of effects goes below it. Close to the RMS before, the residual is "
                 "sensor noise or outside the library.</p>")
    parts.append(_table(["axis", "RMS before", "RMS after", "reduction", "library floor", "pred 0.1 s before", "after",
                         "pred 0.5 s before", "after"],
                        [[a, v["rms_before"], v["rms_after"], v["reduction"], v.get("rms_library_in_sample"),
                          v["pred_0.1s_before"], v["pred_0.1s_after"],
                          v["pred_0.5s_before"], v["pred_0.5s_after"]] for a, v in result["shrink"].items()]))
    parts.append("<img src='shrink.png'>")
    parts.append(_explainable_section(result))
    if result.get("filter") and "error" in result["filter"]:
        parts.append(f"<h3>Firmware filter (replay)</h3><p>not run: {html.escape(str(result['filter']['error']))}</p>")
    elif result.get("filter"):
        f = result["filter"]
        parts.append("<h3>Firmware filter (replay, gyro only)</h3>" + _table(
            ["", "fleet kf mean", "run-to-run CV", "per run"],
            [["vehicle file", f["kf_before"]["mean"], f["kf_before"]["cv"], f["kf_before"]["per_run"]],
             ["corrected vehicle", f["kf_after"]["mean"], f["kf_after"]["cv"], f["kf_after"]["per_run"]]]))
    parts.append("<h2>Corrected vehicle</h2><pre>" + html.escape(json.dumps(result["vehicle_out"], indent=1)) + "</pre>")
    cal = result.get("calibration")
    if cal and cal.get("calibrated"):
        parts.append("<h3>Calibrated with the filter</h3><p>" + html.escape(
            f"The fit logs ({len(cal['logs'])}) replayed gyro only and with the accelerometer, with the corrected file: "
            f"fleet kf {cal['kf_gyro_only']:.4g} and {cal['kf_with_accelerometer']:.4g}; Jxx, Jyy x "
            f"{cal['torque_gain']:.4g} on top of the effects. Replay the file with: {cal['replay_options']['command']}")
            + "</p>")
    elif cal:
        parts.append("<h3>Not calibrated with the filter</h3><p>" + html.escape(str(cal["why"])) + "</p>")
    parts.append("<p>Method and every rule: docs/gap.md in the propid repository.</p></body></html>")
    index = d / "index.html"
    index.write_text("\n".join(parts), encoding="utf-8")
    return index
