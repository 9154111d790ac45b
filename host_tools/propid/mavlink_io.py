"""MAVLink I/O with the propid dialect: the generated pymavlink module, live
connections, .tlog files, and the conversion of propid messages to rows.

The Python dialect module is generated with pymavlink's mavgen from
firmware/mavlink/propid.xml on first use (and again whenever the XML or the
pymavlink version changes) into a git-ignored cache directory:

    $PROPID_MAVLINK_CACHE                        if set, else
    <repo>/build/mavlink/python/                 if writable, else
    ~/.cache/propid/mavlink/

Public helpers (the tlog importer and the commands use these):

    dialect()                 the generated module (MAVLink_*_message classes, enums)
    connect(url)              live link, e.g. "udp:0.0.0.0:14550" (listen) or "udpout:host:port"
    open_tlog(path)           a pymavlink log reader that knows our dialect
    read_tlog(path)           validated iteration over a .tlog's messages (UserError on bad files)
    encode_message(name, ...) one frame as bytes (tests, log writers)
    message_to_dict(msg)      {"mavpackettype": "PROPID_COEFFICIENTS", "time_usec": ..., fields...,
                               "_timestamp": receive time [s], "_sysid": ..., "_compid": ...}
    EstimateRows              turns PROPID_* messages into flat rows (column names of the SITL log)

Run `python -m propid.mavlink_io --help` for the command-line side (dump a tlog
with mavlogdump using our dialect, install the dialect into pymavlink for MAVProxy).
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import hashlib
import io
import importlib.util
import os
import shutil
import socket
import struct
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType
from typing import Any, Iterable, Iterator

from propid.errors import UserError
from propid.units import frd_to_flu, ned_to_enu, rpm_to_rad_s  # noqa: F401 (part of this module's API)

DIALECT_NAME = "propid"
# Bump when the way the module is generated changes, to force regeneration.
_GENERATOR_REVISION = "1"
_INCLUDED_DEFINITIONS = ("common.xml", "standard.xml", "minimal.xml")

# Ground-station identity for what we send (MAV_COMP_ID_MISSIONPLANNER).
GCS_SYSTEM_ID = 255
GCS_COMPONENT_ID = 190

# Message names of our dialect.
MSG_COEFFICIENTS = "PROPID_COEFFICIENTS"
MSG_GYRO = "PROPID_GYRO"
MSG_STATUS = "PROPID_STATUS"
MSG_MODEL = "PROPID_MODEL"
MSG_DAMAGE = "PROPID_DAMAGE"
MAV_SEVERITY_CRITICAL = 2

_dialect_module: ModuleType | None = None


# --------------------------------------------------------------------------
# Dialect generation
# --------------------------------------------------------------------------
def repo_root() -> Path:
    """The source tree this package lives in (host_tools/propid/ -> repo)."""
    return Path(__file__).resolve().parents[2]


def dialect_xml() -> Path:
    """Path of propid.xml ($PROPID_MAVLINK_XML overrides the repository's)."""
    override = os.environ.get("PROPID_MAVLINK_XML")
    path = Path(override) if override else repo_root() / "firmware" / "mavlink" / "propid.xml"
    if not path.is_file():
        raise UserError(f"MAVLink dialect definition not found: {path} "
                        "(set PROPID_MAVLINK_XML to the propid.xml of the source tree)")
    return path


def _writable_dir(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(path, os.W_OK)


def cache_dir() -> Path:
    """Where the generated Python module lives (created on demand)."""
    override = os.environ.get("PROPID_MAVLINK_CACHE")
    if override:
        path = Path(override)
        if not _writable_dir(path):
            raise UserError(f"PROPID_MAVLINK_CACHE={path} is not a writable directory")
        return path
    for path in (repo_root() / "build" / "mavlink" / "python",
                 Path.home() / ".cache" / "propid" / "mavlink"):
        if _writable_dir(path):
            return path
    raise UserError("no writable directory for the generated MAVLink dialect; "
                    "set PROPID_MAVLINK_CACHE")


def _fingerprint(xml: Path) -> str:
    import pymavlink

    digest = hashlib.sha256(xml.read_bytes())
    digest.update(getattr(pymavlink, "__version__", "?").encode())
    digest.update(_GENERATOR_REVISION.encode())
    return digest.hexdigest()


def _generate(xml: Path, module_path: Path) -> None:
    """Run mavgen --lang=Python3 on a copy of the dialect placed beside common.xml."""
    import pymavlink
    from pymavlink.generator import mavgen

    definitions = Path(pymavlink.__file__).parent / "dialects" / "v20"
    with tempfile.TemporaryDirectory(dir=module_path.parent) as work:
        work_dir = Path(work)
        for name in _INCLUDED_DEFINITIONS:
            shutil.copyfile(definitions / name, work_dir / name)
        shutil.copyfile(xml, work_dir / xml.name)
        tmp_module = work_dir / module_path.name
        opts = mavgen.Opts(str(tmp_module), wire_protocol="2.0", language="Python3",
                           validate=True, strict_units=False)
        chatter = io.StringIO()  # mavgen narrates on stdout; keep it for errors only
        try:
            with contextlib.redirect_stdout(chatter):
                ok = mavgen.mavgen(opts, [str(work_dir / xml.name)])
        except Exception as exc:  # mavgen raises many kinds on a bad XML
            raise UserError(f"mavgen failed on {xml}: {exc}\n{chatter.getvalue()}") from exc
        if ok is False or not tmp_module.is_file():
            raise UserError(f"mavgen failed on {xml}:\n{chatter.getvalue()}")
        # Atomic swap: concurrent users see the old or the new module, never half of one.
        os.replace(tmp_module, module_path)


def dialect() -> ModuleType:
    """The pymavlink module generated from propid.xml (regenerated when stale)."""
    global _dialect_module
    if _dialect_module is not None:
        return _dialect_module
    xml = dialect_xml()
    directory = cache_dir()
    module_path = directory / "propid_dialect.py"
    stamp_path = directory / "propid_dialect.stamp"
    fingerprint = _fingerprint(xml)
    stale = (not module_path.is_file() or not stamp_path.is_file()
             or stamp_path.read_text().strip() != fingerprint)
    if stale:
        _generate(xml, module_path)
        tmp_stamp = stamp_path.with_suffix(f".stamp.{os.getpid()}")
        tmp_stamp.write_text(fingerprint + "\n")
        os.replace(tmp_stamp, stamp_path)
    spec = importlib.util.spec_from_file_location("propid_mavlink_dialect", module_path)
    if spec is None or spec.loader is None:
        raise UserError(f"cannot load the generated dialect {module_path}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    _dialect_module = module
    return module


def install_for_mavutil() -> ModuleType:
    """Make `mavutil.set_dialect("propid")` (and mavlogdump's --dialect propid) find our
    module in this process, and select MAVLink 2. Returns the module."""
    module = dialect()
    os.environ["MAVLINK20"] = "1"
    import pymavlink.dialects.v20 as v20_package

    sys.modules[f"pymavlink.dialects.v20.{DIALECT_NAME}"] = module
    setattr(v20_package, DIALECT_NAME, module)
    from pymavlink import mavutil

    mavutil.set_dialect(DIALECT_NAME)
    return module


# --------------------------------------------------------------------------
# Connections and files
# --------------------------------------------------------------------------
def connect(url: str, *, source_system: int = GCS_SYSTEM_ID,
            source_component: int = GCS_COMPONENT_ID, receive_buffer: int = 4 << 20):
    """Open a live MAVLink link with our dialect.

    url: "udp:HOST:PORT" / "udpin:HOST:PORT" listen on HOST:PORT (0.0.0.0 = all),
    "udpout:HOST:PORT" send to HOST:PORT, or any other pymavlink device string.
    """
    install_for_mavutil()
    from pymavlink import mavutil

    listen_address = check_connection(url)
    if listen_address is not None:
        ensure_udp_port_free(*listen_address)
    try:
        conn = mavutil.mavlink_connection(url, source_system=source_system,
                                          source_component=source_component,
                                          dialect=DIALECT_NAME)
    except (OSError, ValueError) as exc:
        raise UserError(f"cannot open {url}: {exc}") from exc
    port = getattr(conn, "port", None)
    if isinstance(port, socket.socket):
        # A fast (not real-time) simulator sends bursts; a bigger buffer loses nothing.
        try:
            port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer)
        except OSError:
            pass
    return conn


_UDP_LISTEN = ("udp", "udpin")
_NETWORK_SCHEMES = _UDP_LISTEN + ("udpout", "udpbcast", "tcp", "tcpin")


def check_connection(url: str) -> tuple[str, int] | None:
    """Check a connection string before opening it; UserError naming what is wrong.
    Returns (host, port) for a UDP link we listen on, else None."""
    usage = ("expected udp:HOST:PORT or udpin:HOST:PORT (listen), udpout:HOST:PORT, tcp:HOST:PORT, "
             "tcpin:HOST:PORT, or a serial device such as /dev/ttyACM0[,BAUD]")
    scheme, _, rest = url.partition(":")
    if scheme not in _NETWORK_SCHEMES:
        if url.startswith("/") or url.upper().startswith("COM"):
            return None  # a serial device: pymavlink names the problem if it cannot open it
        raise UserError(f"bad connection '{url}': {usage}")
    host, sep, port_text = rest.rpartition(":")
    if not sep or not host:
        raise UserError(f"bad connection '{url}': {usage}")
    try:
        port = int(port_text)
    except ValueError:
        raise UserError(f"bad connection '{url}': port '{port_text}' is not a number ({usage})") from None
    if not 0 < port < 65536:
        raise UserError(f"bad connection '{url}': port {port} outside 1..65535")
    return (host, port) if scheme in _UDP_LISTEN else None


def ensure_udp_port_free(host: str, port: int) -> None:
    """pymavlink binds a listening UDP socket with SO_REUSEADDR, so on Linux a second
    listener on the same port binds too and takes the traffic from the first, which then
    silently sees nothing. A bind without SO_REUSEADDR fails if anyone holds the port:
    try that first and refuse to share."""
    for attempt in range(3):  # a port held only for an instant (another tool's probe) is not "in use"
        probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            probe.bind((host, port))
            return
        except OSError as exc:
            if exc.errno != errno.EADDRINUSE:
                raise UserError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
        finally:
            probe.close()
        time.sleep(0.1)
    raise UserError(f"UDP port {port} on {host} is already in use (another propid listen/log or a "
                    "ground station?): stop it, or forward the stream to another port")


def _check_file(path: str | os.PathLike) -> Path:
    path = Path(path)
    if not path.exists():
        raise UserError(f"{path}: no such file")
    if not path.is_file():
        raise UserError(f"{path}: not a regular file")
    if path.stat().st_size == 0:
        raise UserError(f"{path}: empty file")
    return path


def open_tlog(path: str | os.PathLike):
    """A pymavlink reader for a .tlog (8-byte big-endian microsecond timestamp before
    each frame) that decodes our dialect. Prefer read_tlog() for validated reading."""
    path = _check_file(path)
    install_for_mavutil()
    from pymavlink import mavutil

    # The streaming reader, not mavlink_connection(): that picks the memory-mapped
    # indexer for files, which crashes on damaged data, and treats a ':' in a file name
    # as a network address.
    try:
        return mavutil.mavlogfile(str(path), robust_parsing=True)
    except OSError as exc:
        raise UserError(f"{path}: cannot open: {exc}") from exc


class TlogReport:
    """What read_tlog() saw: good frames, undecodable chunks, trailing bytes."""

    def __init__(self, path: Path, size: int):
        self.path = path
        self.size = size
        self.messages = 0
        self.bad_chunks = 0
        self.bad_bytes = 0
        self.trailing_bytes = 0

    def warnings(self) -> list[str]:
        notes = []
        if self.bad_chunks:
            notes.append(f"{self.path}: skipped {self.bad_chunks} corrupt chunk(s), "
                         f"{self.bad_bytes} bytes")
        if self.trailing_bytes:
            notes.append(f"{self.path}: file ends inside a frame (truncated?): "
                         f"last {self.trailing_bytes} bytes ignored")
        return notes


def read_tlog(path: str | os.PathLike, types: Iterable[str] | None = None,
              progress: bool = False, report: TlogReport | None = None,
              max_bad_fraction: float = 0.5) -> Iterator[Any]:
    """Yield the decodable messages of a .tlog (optionally only `types`).

    Raises UserError when the file is missing/empty, holds no MAVLink frame at all, or
    more than max_bad_fraction of its bytes are not valid frames. Isolated corrupt
    frames and a truncated last frame are skipped and described in `report`
    (and on stderr when report is None) so a damaged log still gives its data.
    """
    path = _check_file(path)
    size = path.stat().st_size
    own_report = report is None
    report = report or TlogReport(path, size)
    wanted = set(types) if types is not None else None
    conn = open_tlog(path)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=size, unit="B", unit_scale=True, desc=path.name, leave=False,
                   disable=None)  # None: no bar when stderr is not a terminal
    position = 0
    try:
        while True:
            try:
                msg = conn.recv_msg()
            except Exception as exc:  # pymavlink can raise on pathological bytes
                raise UserError(f"{path}: corrupt tlog near byte {conn.f.tell()}: {exc}") from exc
            if bar is not None:
                now = conn.f.tell()
                bar.update(now - position)
                position = now
            if msg is None:
                break
            kind = msg.get_type()
            if kind == "BAD_DATA":
                report.bad_chunks += 1
                report.bad_bytes += len(msg.get_msgbuf())
                continue
            if kind.startswith("UNKNOWN"):
                continue
            report.messages += 1
            if wanted is None or kind in wanted:
                yield msg
        report.trailing_bytes = len(getattr(conn.mav, "buf", b"")) - getattr(conn.mav, "buf_index", 0)
        report.trailing_bytes = max(report.trailing_bytes, 0)
    finally:
        if bar is not None:
            bar.close()
        conn.close()
    if report.messages == 0:
        raise UserError(f"{path}: no MAVLink frame found (not a .tlog, or corrupt)")
    if report.bad_bytes > max_bad_fraction * size:
        raise UserError(f"{path}: corrupt: {report.bad_bytes} of {size} bytes are not "
                        "valid MAVLink frames")
    if own_report:
        for note in report.warnings():
            print(f"warning: {note}", file=sys.stderr)


class TlogWriter:
    """Writes frames as a .tlog: 8-byte big-endian receive time [us] + raw frame, the
    layout pymavlink's mavlogdump (and MAVProxy, QGroundControl) read."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        try:
            self._file = open(self.path, "wb")
        except OSError as exc:
            raise UserError(f"cannot write {self.path}: {exc}") from exc
        self.frames = 0
        self.bytes = 0

    def write(self, frame: bytes, receive_time_s: float | None = None) -> None:
        t = time.time() if receive_time_s is None else receive_time_s
        # mavutil stores the link number in the 2 low bits of the stamp: keep them 0.
        usec = int(t * 1e6) & ~3
        self._file.write(struct.pack(">Q", usec) + bytes(frame))
        self.frames += 1
        self.bytes += 8 + len(frame)

    def flush(self) -> None:
        self._file.flush()

    def close(self) -> None:
        if not self._file.closed:
            self._file.flush()
            self._file.close()

    def __enter__(self) -> "TlogWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def encode_message(name: str, *, system_id: int = 1, component_id: int = 1,
                   sequence: int = 0, **fields) -> bytes:
    """One MAVLink 2 frame of message `name` (e.g. "PROPID_COEFFICIENTS") with the given
    fields (all of them, by name), as bytes. For tests, simulators and log writers."""
    module = dialect()
    cls = getattr(module, f"MAVLink_{name.lower()}_message", None)
    if cls is None:
        raise UserError(f"unknown MAVLink message {name}")
    missing = [f for f in cls.fieldnames if f not in fields]
    if missing:
        raise UserError(f"{name}: missing field(s) {', '.join(missing)}")
    encoder = module.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
    encoder.seq = sequence % 256
    return bytes(cls(**fields).pack(encoder))


# --------------------------------------------------------------------------
# Messages -> dicts and rows
# --------------------------------------------------------------------------
def message_to_dict(msg) -> dict[str, Any]:
    """All fields of a pymavlink message by name (arrays as lists), plus
    "mavpackettype" (message name), "_timestamp" (receive time [s]: the tlog stamp or
    the live receive time), "_sysid" and "_compid". Units and frames are the dialect's:
    MAVLink FRD/NED, SI (see docs/telemetry.md)."""
    out = msg.to_dict()
    for key, value in list(out.items()):
        if isinstance(value, (bytes, bytearray)):
            out[key] = list(value)
    out["_timestamp"] = getattr(msg, "_timestamp", None)
    out["_sysid"] = msg.get_srcSystem()
    out["_compid"] = msg.get_srcComponent()
    return out


def damage_event(msg) -> dict[str, Any]:
    """A PROPID_DAMAGE message as a detection: filter time [s], the isolated rotor
    (1-based, as on the wire), the detection count and the rotors flagged since boot
    (1-based, from damaged_mask)."""
    mask = int(msg.damaged_mask)
    return {"time_s": msg.time_usec * 1e-6, "rotor": int(msg.rotor),
            "detections": int(msg.detections),
            "damaged_rotors": [i + 1 for i in range(16) if mask >> i & 1]}


def format_damage_event(event: dict[str, Any]) -> str:
    rotors = ", ".join(str(r) for r in event["damaged_rotors"]) or "-"
    return (f"DAMAGE t={event['time_s']:.3f} s: rotor {event['rotor']} "
            f"(detection {event['detections']}; damaged rotors {rotors})")


def statustext(msg) -> tuple[int, str]:
    """(severity, text) of a STATUSTEXT (text without its NUL padding)."""
    text = msg.text
    if isinstance(text, (bytes, bytearray)):
        text = text.decode("utf-8", errors="replace")
    return int(msg.severity), text.rstrip("\x00")


def estimate_columns(rotor_count: int) -> list[str]:
    """CSV columns of `propid log`: the SITL flight log's names for the same quantities
    (body FLU), so plots and analyses read either file."""
    cols = ["t", "rotor_count"]
    for i in range(1, rotor_count + 1):
        cols += [f"est_kf_{i}", f"std_kf_{i}"]
    for i in range(1, rotor_count + 1):
        cols += [f"est_km_{i}", f"std_km_{i}"]
    cols += ["est_bg_x", "est_bg_y", "est_bg_z", "std_bg_x", "std_bg_y", "std_bg_z",
             "est_wx", "est_wy", "est_wz",
             "kf_converging", "kf_converged", "km_converging", "km_converged",
             "health", "gyro_accepted", "rejected_total", "gated_total", "cov_repairs",
             # the optional terms (PROPID_MODEL; empty when the vehicle sends none)
             "est_dist_x", "est_dist_y", "est_dist_z", "std_dist_x", "std_dist_y", "std_dist_z",
             "est_accel_bias_z", "std_accel_bias_z", "est_torque_scale", "std_torque_scale",
             "esc_delay_s", "model_terms"]
    return cols


class EstimateRows:
    """Feed it messages in arrival order; each PROPID_COEFFICIENTS yields one row
    combined with the latest PROPID_GYRO, PROPID_STATUS and PROPID_MODEL (columns:
    estimate_columns)."""

    def __init__(self) -> None:
        self.rotor_count: int | None = None
        self._gyro = None
        self._status = None
        self._model = None

    def feed(self, msg) -> dict[str, Any] | None:
        kind = msg.get_type()
        if kind == MSG_GYRO:
            self._gyro = msg
            return None
        if kind == MSG_MODEL:
            self._model = msg
            return None
        if kind == MSG_STATUS:
            self._status = msg
            return None
        if kind != MSG_COEFFICIENTS:
            return None
        count = int(msg.rotor_count)
        if not 1 <= count <= 8:
            return None
        if self.rotor_count is None:
            self.rotor_count = count
        elif count != self.rotor_count:
            raise UserError(f"rotor count changed from {self.rotor_count} to {count} "
                            "within one recording")
        nan = float("nan")
        row: dict[str, Any] = {"t": msg.time_usec * 1e-6, "rotor_count": count}
        for i in range(count):
            row[f"est_kf_{i + 1}"] = msg.thrust_coeff[i]
            row[f"std_kf_{i + 1}"] = msg.thrust_coeff_std[i]
            row[f"est_km_{i + 1}"] = msg.drag_coeff[i]
            row[f"std_km_{i + 1}"] = msg.drag_coeff_std[i]
        row["kf_converging"] = msg.thrust_coeff_converging
        row["kf_converged"] = msg.thrust_coeff_converged
        row["km_converging"] = msg.drag_coeff_converging
        row["km_converged"] = msg.drag_coeff_converged
        gyro = self._gyro
        if gyro is not None:
            bias = frd_to_flu(gyro.gyro_bias)
            rate = frd_to_flu(gyro.body_rate)
            row.update(est_bg_x=bias[0], est_bg_y=bias[1], est_bg_z=bias[2],
                       std_bg_x=gyro.gyro_bias_std[0], std_bg_y=gyro.gyro_bias_std[1],
                       std_bg_z=gyro.gyro_bias_std[2],
                       est_wx=rate[0], est_wy=rate[1], est_wz=rate[2], health=gyro.health)
        else:
            row.update({k: nan for k in ("est_bg_x", "est_bg_y", "est_bg_z", "std_bg_x",
                                         "std_bg_y", "std_bg_z", "est_wx", "est_wy", "est_wz",
                                         "health")})
        status = self._status
        if status is not None:
            row.update(gyro_accepted=status.gyro_accepted,
                       rejected_total=status.rejected_total,
                       gated_total=sum(status.axis_gated), cov_repairs=status.cov_repairs)
            if gyro is None:
                row["health"] = status.health
        else:
            row.update(gyro_accepted=nan, rejected_total=nan, gated_total=nan, cov_repairs=nan)
        row.update(model_columns(self._model))
        return row


def model_columns(model) -> dict[str, Any]:
    """The PROPID_MODEL part of a row, body FLU (None: every column NaN)."""
    nan = float("nan")
    names = ("est_dist_x", "est_dist_y", "est_dist_z", "std_dist_x", "std_dist_y", "std_dist_z",
             "est_accel_bias_z", "std_accel_bias_z", "est_torque_scale", "std_torque_scale",
             "esc_delay_s", "model_terms")
    if model is None:
        return {name: nan for name in names}
    torque = frd_to_flu(model.disturbance_torque)
    values = [*torque, *model.disturbance_torque_std, -model.accel_bias, model.accel_bias_std,
              model.torque_scale, model.torque_scale_std, model.esc_delay_us * 1e-6, model.terms]
    return dict(zip(names, values))


# --------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------
def send_reset(conn, rotor: int = -1, *, target_system: int = 1, target_component: int = 1,
               timeout: float = 2.0) -> int:
    """Send MAV_CMD_PROPID_RESET (rotor index or -1 = all) and wait for its COMMAND_ACK.
    Returns the MAV_RESULT; raises UserError when no acknowledgement arrives."""
    module = dialect()
    command = module.MAV_CMD_PROPID_RESET
    deadline = time.monotonic() + timeout
    conn.mav.command_long_send(target_system, target_component, command, 0,
                               float(rotor), 0, 0, 0, 0, 0, 0)
    while time.monotonic() < deadline:
        msg = conn.recv_match(type="COMMAND_ACK", blocking=True,
                              timeout=max(0.0, deadline - time.monotonic()))
        if msg is not None and msg.command == command:
            return int(msg.result)
    raise UserError(f"no COMMAND_ACK for MAV_CMD_PROPID_RESET within {timeout:g} s")


# --------------------------------------------------------------------------
# Command line: python -m propid.mavlink_io ...
# --------------------------------------------------------------------------
def _main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m propid.mavlink_io",
        description="propid MAVLink dialect helpers.")
    sub = parser.add_subparsers(dest="action", required=True)
    sub.add_parser("generate", help="generate the Python dialect module and print its path")
    dump = sub.add_parser("mavlogdump",
                          help="run pymavlink's mavlogdump with our dialect "
                               "(arguments after -- go to mavlogdump)")
    dump.add_argument("args", nargs=argparse.REMAINDER)
    sub.add_parser("install-dialect",
                   help="copy the generated module into pymavlink's dialects/v20 as "
                        "'propid' (lets MAVProxy --dialect propid and mavlogdump.py "
                        "--dialect propid find it)")
    args = parser.parse_args(argv)
    try:
        if args.action == "generate":
            module = dialect()
            print(module.__file__)
            return 0
        if args.action == "mavlogdump":
            import runpy

            rest = [a for a in args.args if a != "--"]
            names = [a for a in rest if not a.startswith("-")]
            if names and not any(Path(name).is_file() for name in names):
                # pymavlink takes a path that is not a file for a serial port (a traceback)
                raise UserError(f"cannot read {names[-1]}: no such file (mavlogdump reads a .tlog)")
            install_for_mavutil()
            sys.argv = ["mavlogdump.py", "--dialect", DIALECT_NAME] + rest
            runpy.run_module("pymavlink.tools.mavlogdump", run_name="__main__")
            return 0
        if args.action == "install-dialect":
            import pymavlink

            module = dialect()
            target = Path(pymavlink.__file__).parent / "dialects" / "v20" / f"{DIALECT_NAME}.py"
            shutil.copyfile(module.__file__, target)
            shutil.copyfile(dialect_xml(), target.with_suffix(".xml"))
            print(f"installed {target}")
            return 0
    except UserError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 2


if __name__ == "__main__":
    sys.exit(_main())
