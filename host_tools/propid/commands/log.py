"""`propid log`: record propid telemetry to a raw .tlog and a CSV of estimates."""

from __future__ import annotations

import argparse
import csv
import math
import signal
import sys
import time
from pathlib import Path

from propid import mavlink_io
from propid.errors import UserError
from propid.outputs import check_writable, make_parents

NAME = "log"
HELP = "record MAVLink telemetry to a .tlog (raw frames) and/or a CSV of the estimates"

# Flush the files this often so a kill loses at most this much.
FLUSH_PERIOD_S = 1.0


def positive_seconds(text: str) -> float:
    """argparse type of --timeout, --duration, --stop-when-idle (here and in `propid listen`): a finite time > 0
    (a negative timeout used to fail at once with "no data within -1 s")."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected seconds") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r}: must be a positive number of seconds")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--connect", default="udp:0.0.0.0:14550",
                        help="MAVLink link to record (default: listen on udp:0.0.0.0:14550)")
    parser.add_argument("--tlog", type=Path,
                        help="write every frame here, timestamped (readable by mavlogdump)")
    parser.add_argument("--csv", type=Path,
                        help="write one row per PROPID_COEFFICIENTS message here "
                             "(columns as in the SITL flight log, body FLU)")
    parser.add_argument("--duration", type=positive_seconds, metavar="S",
                        help="stop after S seconds (default: until Ctrl-C)")
    parser.add_argument("--timeout", type=positive_seconds, default=10.0, metavar="S",
                        help="fail if nothing arrives within S seconds (default 10)")
    parser.add_argument("--stop-when-idle", type=positive_seconds, metavar="S",
                        help="stop once data has arrived and then nothing for S seconds "
                             "(e.g. the simulator finished)")
    parser.add_argument("--no-progress", "--quiet", dest="quiet", action="store_true",
                        help="no progress line (--quiet: the older spelling)")


class Recorder:
    """Writes what arrives; closing flushes both files. The files are opened when the
    first frame arrives, so a recording that receives nothing leaves existing files as
    they were (a failed `propid log` must not wipe yesterday's recording)."""

    def __init__(self, tlog: Path | None, csv_path: Path | None):
        for path, option in ((tlog, "--tlog"), (csv_path, "--csv")):
            if path is not None:
                check_writable(path, option)
        self.tlog_path = tlog
        self.tlog = None
        self.csv_path = csv_path
        self._csv_file = None
        self._csv_writer = None
        self._columns: list[str] | None = None
        self.rows = EstimateCounter()
        self.assembler = mavlink_io.EstimateRows()
        self.frames = 0
        self.bad = 0
        self.interrupted = False
        self.by_type: dict[str, int] = {}

    def _open(self) -> None:
        for path in (self.tlog_path, self.csv_path):
            if path is not None:
                make_parents(path)
        if self.tlog_path is not None:
            self.tlog = mavlink_io.TlogWriter(self.tlog_path)
        if self.csv_path is not None:
            try:
                self._csv_file = open(self.csv_path, "w", newline="")
            except OSError as exc:
                raise UserError(f"cannot write {self.csv_path}: {exc}") from exc

    def handle(self, msg, receive_time: float) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self.bad += 1
            return
        if self.frames == 0:
            self._open()
        self.frames += 1
        self.by_type[kind] = self.by_type.get(kind, 0) + 1
        if self.tlog is not None:
            self.tlog.write(msg.get_msgbuf(), receive_time)
        row = self.assembler.feed(msg)
        if row is not None:
            self.rows.add(row)
            if self._csv_file is not None:
                if self._csv_writer is None:
                    self._columns = mavlink_io.estimate_columns(row["rotor_count"])
                    self._csv_writer = csv.writer(self._csv_file)
                    self._csv_writer.writerow(self._columns)
                self._csv_writer.writerow([_fmt(row.get(c, math.nan)) for c in self._columns])

    def flush(self) -> None:
        if self.tlog is not None:
            self.tlog.flush()
        if self._csv_file is not None:
            self._csv_file.flush()

    def close(self) -> None:
        if self.tlog is not None:
            self.tlog.close()
        if self._csv_file is not None:
            if self._csv_writer is None:  # frames but no estimate: still a valid (header) file
                csv.writer(self._csv_file).writerow(mavlink_io.estimate_columns(0))
            self._csv_file.close()


class EstimateCounter:
    def __init__(self) -> None:
        self.count = 0
        self.last: dict | None = None

    def add(self, row: dict) -> None:
        self.count += 1
        self.last = row


def _fmt(value) -> str:
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    return str(value)


def _terminate_as_interrupt(signum, frame):  # SIGTERM ends like Ctrl-C: files are kept
    raise KeyboardInterrupt


def record(connect: str, tlog: Path | None = None, csv_path: Path | None = None,
           duration: float | None = None, timeout: float = 10.0,
           stop_when_idle: float | None = None, quiet: bool = True) -> Recorder:
    """Record until duration, idle, or Ctrl-C/SIGTERM; returns the (closed) recorder."""
    if tlog is None and csv_path is None:
        raise UserError("nothing to write: give --tlog and/or --csv")
    conn = mavlink_io.connect(connect)
    recorder = Recorder(tlog, csv_path)
    start = time.monotonic()
    last_data = None
    last_flush = start
    last_print = start
    interrupted = False
    previous_handler = None
    try:
        previous_handler = signal.signal(signal.SIGTERM, _terminate_as_interrupt)
    except ValueError:  # not the main thread
        previous_handler = None
    try:
        while True:
            now = time.monotonic()
            if duration is not None and now - start >= duration:
                break
            if last_data is None and now - start >= timeout:
                raise UserError(f"no MAVLink data on {connect} within {timeout:g} s "
                                "(is the vehicle/SITL sending there?)")
            if (stop_when_idle is not None and last_data is not None
                    and now - last_data >= stop_when_idle):
                break
            msg = conn.recv_match(blocking=True, timeout=0.05)
            if msg is not None:
                last_data = time.monotonic()
                recorder.handle(msg, time.time())
            if now - last_flush >= FLUSH_PERIOD_S:
                recorder.flush()
                last_flush = now
            if not quiet and now - last_print >= 1.0:
                last_print = now
                print(f"\r{recorder.frames} frames, {recorder.rows.count} estimates",
                      end="", file=sys.stderr, flush=True)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        recorder.close()
        conn.close()
        if previous_handler is not None:
            signal.signal(signal.SIGTERM, previous_handler)
        if not quiet:
            print("", file=sys.stderr)
    recorder.interrupted = interrupted
    if not interrupted and recorder.frames == 0:
        raise UserError(f"no MAVLink data arrived on {connect}")
    return recorder


def run(args: argparse.Namespace) -> int:
    recorder = record(args.connect, args.tlog, args.csv, args.duration, args.timeout,
                      args.stop_when_idle, quiet=args.quiet)
    written = []
    if args.tlog:
        written.append(f"{args.tlog} ({recorder.frames} frames)")
    if args.csv:
        written.append(f"{args.csv} ({recorder.rows.count} estimate rows)")
    note = "interrupted; kept " if recorder.interrupted else "wrote "
    print(note + ", ".join(written), file=sys.stderr)
    if recorder.bad:
        print(f"warning: {recorder.bad} undecodable chunks skipped", file=sys.stderr)
    return 0
