"""`propid listen`: live view of the propid estimates arriving over MAVLink."""

from __future__ import annotations

import argparse
import sys
import time

from propid import mavlink_io
from propid.commands.log import positive_seconds
from propid.errors import UserError

NAME = "listen"
HELP = "live view of kf/km (+-1 sigma) per rotor, gyro bias and health from MAVLink telemetry"

REFRESH_S = 0.5
SILENT_S = 1.0  # no propid message for this long: the screen says its figures are the last received
PLOT_HISTORY_S = 120.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--connect", default="udp:0.0.0.0:14550",
                        help="MAVLink link (default: listen on udp:0.0.0.0:14550)")
    parser.add_argument("--plot", action="store_true",
                        help="live matplotlib plot of the estimates (needs a display)")
    parser.add_argument("--timeout", type=positive_seconds, default=10.0, metavar="S",
                        help="fail if no propid message arrives within S seconds (default 10)")
    parser.add_argument("--duration", type=positive_seconds, metavar="S",
                        help="stop after S seconds (default: until Ctrl-C)")
    parser.add_argument("--reset", type=reset_target, metavar="ROTOR|all",
                        help="first send MAV_CMD_PROPID_RESET for rotor ROTOR as this screen numbers the rotors "
                             "(1..N; the command's param1 is the 0-based index ROTOR - 1) or for all (the whole "
                             "filter; -1 also means all) and report the acknowledgement")


def reset_target(text: str) -> int:
    """--reset: the rotor as the screen numbers it (1..N) or all; returns the command's param1, the 0-based
    rotor index or -1 for the whole filter (docs/telemetry.md MAV_CMD_PROPID_RESET)."""
    if text.strip().lower() in ("all", "-1"):
        return -1
    try:
        rotor = int(text)
    except ValueError:
        rotor = 0
    if rotor < 1:
        raise argparse.ArgumentTypeError(f"expected a rotor number 1..N (as the screen shows them) or all, got {text!r}")
    return rotor - 1


def reset_label(param1: int) -> str:
    return "all rotors" if param1 < 0 else f"rotor {param1 + 1}"


def health_names(health: int) -> list[str]:
    """Names of the set PROPID_HEALTH_FLAGS bits (without the prefix)."""
    enum = mavlink_io.dialect().enums.get("PROPID_HEALTH_FLAGS", {})
    names = []
    for value, entry in sorted(enum.items()):
        if value & health and not entry.name.endswith("_ENUM_END"):
            names.append(entry.name.replace("PROPID_HEALTH_FLAGS_", ""))
    return names


def model_term_names(terms: int) -> list[str]:
    """Names of the set PROPID_MODEL_TERMS bits (without the prefix)."""
    enum = mavlink_io.dialect().enums.get("PROPID_MODEL_TERMS", {})
    return [entry.name.replace("PROPID_MODEL_TERMS_", "") for value, entry in sorted(enum.items())
            if value & terms and not entry.name.endswith("_ENUM_END")]


def _mask_state(i: int, converging: int, converged: int) -> str:
    if converged >> i & 1:
        return "converged"
    if converging >> i & 1:
        return "converging"
    return "-"


def format_model(model) -> list[str]:
    """The PROPID_MODEL lines of the screen (body FLU)."""
    terms = int(model.terms)
    names = model_term_names(terms)
    lines = [f"model terms {' '.join(names) or 'none'}   ESC delay held {model.esc_delay_us * 1e-3:+.1f} ms"
             f"   delay overflows {model.delay_overflows}"]
    if "DISTURBANCE" in names:
        torque = mavlink_io.frd_to_flu(model.disturbance_torque)
        lines.append("disturbance torque FLU [N m]  " + "  ".join(
            f"{a} {t:+.3e} +-{s:.1e}" for a, t, s in zip("xyz", torque, model.disturbance_torque_std)))
    if "ACCEL" in names:
        lines.append(f"accel z bias FLU {-model.accel_bias:+.3f} +-{model.accel_bias_std:.3f} m/s^2"
                     f"   accepted {model.accel_accepted}  gated {model.accel_gated}")
    if "TORQUE_SCALE" in names:
        lines.append(f"thrust-torque scale {model.torque_scale:.4f} +-{model.torque_scale_std:.4f}")
    return lines


def format_view(coeffs, gyro, status, frames: int, source: str, model=None,
                damage: list[str] | None = None, silent_s: float | None = None) -> str:
    """The text screen for the latest messages (any of them may be None); damage: the
    damage detections and CRITICAL texts received so far (latest last); silent_s: seconds
    since the last propid message when the stream has gone quiet (None while it flows)."""
    lines = [f"propid listen  {source}  frames {frames}"]
    if silent_s is not None:
        lines.append(f"no propid message for {silent_s:.1f} s: the figures below are the last received")
    if coeffs is None:
        lines.append("waiting for PROPID_COEFFICIENTS ...")
        return "\n".join(lines + (damage or [])[-4:])
    lines.append(f"filter time {coeffs.time_usec * 1e-6:10.3f} s   rotors {coeffs.rotor_count}")
    lines.append(f"{'rotor':>5}  {'kf [N/(rad/s)^2]':>17} {'+-1sigma':>9} {'':10}"
                 f"  {'km [N m/(rad/s)^2]':>18} {'+-1sigma':>9} {'':10}")
    for i in range(min(int(coeffs.rotor_count), 8)):
        kf, kf_std = coeffs.thrust_coeff[i], coeffs.thrust_coeff_std[i]
        km, km_std = coeffs.drag_coeff[i], coeffs.drag_coeff_std[i]
        kf_state = _mask_state(i, coeffs.thrust_coeff_converging, coeffs.thrust_coeff_converged)
        km_state = _mask_state(i, coeffs.drag_coeff_converging, coeffs.drag_coeff_converged)
        kf_rel = f"({100 * kf_std / kf:4.1f}%)" if kf > 0 else ""
        km_rel = f"({100 * km_std / km:4.1f}%)" if km > 0 else ""
        lines.append(f"{i + 1:>5}  {kf:17.4e} {kf_std:9.2e} {kf_rel:>8} {kf_state:<10}"
                     f"  {km:18.4e} {km_std:9.2e} {km_rel:>8} {km_state:<10}")
    if gyro is not None:
        bias = mavlink_io.frd_to_flu(gyro.gyro_bias)
        std = gyro.gyro_bias_std
        lines.append("gyro bias FLU [rad/s]  " + "  ".join(
            f"{a} {b:+.5f} +-{s:.5f}" for a, b, s in zip("xyz", bias, std)))
        rate = mavlink_io.frd_to_flu(gyro.body_rate)
        lines.append("body rate FLU [rad/s]  " + "  ".join(
            f"{a} {w:+.4f}" for a, w in zip("xyz", rate)))
        names = health_names(int(gyro.health))
        lines.append(f"health 0x{int(gyro.health):02x}  {' '.join(names) or 'ok'}")
    if status is not None:
        lines.append(f"gyro accepted {status.gyro_accepted}  rotor accepted {status.rotor_accepted}"
                     f"  gated {list(status.axis_gated)}  rejected {status.rejected_total}"
                     f"  cov repairs {status.cov_repairs}")
    if model is not None:
        lines += format_model(model)
    if damage:
        lines += damage[-4:]
    return "\n".join(lines)


class LivePlot:
    """A rolling matplotlib window of kf and km per rotor with +-1 sigma bands."""

    def __init__(self):
        import matplotlib
        import matplotlib.pyplot as plt

        backend = matplotlib.get_backend().lower()
        if backend in ("agg", "pdf", "svg", "ps", "cairo", "template") or "inline" in backend:
            raise UserError("--plot needs a display (interactive matplotlib backend); "
                            "record with `propid log` and draw with `propid plot` instead")
        self.plt = plt
        plt.ion()
        self.fig, (self.ax_kf, self.ax_km) = plt.subplots(2, 1, sharex=True, figsize=(9, 6))
        self.t: list[float] = []
        self.kf: list[list[float]] = []
        self.kf_std: list[list[float]] = []
        self.km: list[list[float]] = []
        self.km_std: list[list[float]] = []

    def add(self, coeffs) -> None:
        n = int(coeffs.rotor_count)
        self.t.append(coeffs.time_usec * 1e-6)
        self.kf.append(list(coeffs.thrust_coeff[:n]))
        self.kf_std.append(list(coeffs.thrust_coeff_std[:n]))
        self.km.append(list(coeffs.drag_coeff[:n]))
        self.km_std.append(list(coeffs.drag_coeff_std[:n]))
        while self.t and self.t[-1] - self.t[0] > PLOT_HISTORY_S:
            for series in (self.t, self.kf, self.kf_std, self.km, self.km_std):
                series.pop(0)

    def draw(self) -> None:
        import numpy as np

        if not self.t:
            return
        t = np.asarray(self.t)
        for ax, mean, std, label in ((self.ax_kf, self.kf, self.kf_std, "kf [N/(rad/s)^2]"),
                                     (self.ax_km, self.km, self.km_std, "km [N m/(rad/s)^2]")):
            ax.clear()
            m, s = np.asarray(mean), np.asarray(std)
            for i in range(m.shape[1]):
                ax.plot(t, m[:, i], label=f"rotor {i + 1}")
                ax.fill_between(t, m[:, i] - s[:, i], m[:, i] + s[:, i], alpha=0.2)
            ax.set_ylabel(label)
            ax.grid(True, alpha=0.3)
            ax.legend(loc="upper right", fontsize=7)
        self.ax_km.set_xlabel("filter time [s]")
        self.plt.pause(0.001)


def run(args: argparse.Namespace) -> int:
    live_plot = LivePlot() if args.plot else None
    conn = mavlink_io.connect(args.connect)
    interactive = sys.stdout.isatty()
    start = time.monotonic()
    last_draw = 0.0
    coeffs = gyro = status = model = None
    damage: list[str] = []
    frames = 0
    got_propid = False
    reset_pending = args.reset is not None
    reset_result = None
    interrupted = False
    last_propid = start
    printed = None  # (frames, silent) of the last screen printed to a pipe or file

    def silence(at: float) -> float | None:
        return at - last_propid if got_propid and at - last_propid >= SILENT_S else None
    try:
        while True:
            now = time.monotonic()
            if args.duration is not None and now - start >= args.duration:
                break
            if not got_propid and now - start >= args.timeout:
                what = "MAVLink data" if frames == 0 else "propid messages (other MAVLink did arrive)"
                raise UserError(f"no {what} on {args.connect} within {args.timeout:g} s")
            msg = conn.recv_match(blocking=True, timeout=0.05)
            if msg is not None and msg.get_type() != "BAD_DATA":
                frames += 1
                kind = msg.get_type()
                if kind.startswith("PROPID_"):
                    last_propid = now
                if kind == mavlink_io.MSG_COEFFICIENTS:
                    coeffs, got_propid = msg, True
                    if live_plot is not None:
                        live_plot.add(msg)
                elif kind == mavlink_io.MSG_GYRO:
                    gyro, got_propid = msg, True
                elif kind == mavlink_io.MSG_STATUS:
                    status, got_propid = msg, True
                elif kind == mavlink_io.MSG_MODEL:
                    model, got_propid = msg, True
                elif kind == mavlink_io.MSG_DAMAGE:
                    got_propid = True
                    line = mavlink_io.format_damage_event(mavlink_io.damage_event(msg))
                    damage.append(line)
                    print(line, file=sys.stderr, flush=True)
                elif kind == "STATUSTEXT":
                    severity, text = mavlink_io.statustext(msg)
                    if severity <= mavlink_io.MAV_SEVERITY_CRITICAL:
                        damage.append(f"STATUSTEXT: {text}")
                        print(f"STATUSTEXT: {text}", file=sys.stderr, flush=True)
                elif kind == "HEARTBEAT" and reset_pending:
                    reset_pending = False
                    result = mavlink_io.send_reset(conn, args.reset,
                                                   target_system=msg.get_srcSystem(),
                                                   target_component=msg.get_srcComponent())
                    reset_result = mavlink_io.dialect().enums["MAV_RESULT"][result].name
                    print(f"MAV_CMD_PROPID_RESET {reset_label(args.reset)}: {reset_result}", flush=True)
            if now - last_draw >= REFRESH_S:
                last_draw = now
                silent = silence(now)
                view = format_view(coeffs, gyro, status, frames, args.connect, model, damage, silent)
                if interactive:
                    print("\033[H\033[J" + view, flush=True)
                elif printed != (frames, silent is not None):
                    # a pipe or file gets a screen when something arrived, and once when the
                    # stream goes quiet, not the same screen every refresh
                    printed = (frames, silent is not None)
                    print(view + "\n", flush=True)
                if live_plot is not None:
                    live_plot.draw()
    except KeyboardInterrupt:
        interrupted = True
    finally:
        conn.close()
    print(format_view(coeffs, gyro, status, frames, args.connect, model, silent_s=silence(time.monotonic())))
    if not got_propid and not interrupted:
        what = "MAVLink data" if frames == 0 else "propid messages (other MAVLink did arrive)"
        raise UserError(f"no {what} on {args.connect} within --duration {args.duration:g} s")
    if args.reset is not None:
        if reset_result is None:
            raise UserError("MAV_CMD_PROPID_RESET was not sent: no HEARTBEAT arrived to address it to")
        if reset_result != "MAV_RESULT_ACCEPTED":
            raise UserError(f"MAV_CMD_PROPID_RESET {reset_label(args.reset)} refused: {reset_result}")
    return 0
