"""The motor commands as the rotor input's instrument (docs/math.md §16): the log's cmd_i
columns, pushed with propid_push_motor_command, and the per-log rule for the first
stage's lag.

The lag rule uses the log's commands and rotor speeds only (never a coefficient): the lag
from LAG_CANDIDATES_S whose lagged command explains the most of the increments of
Omega_i^2 (fit on the increments of z and z^2, per rotor, pooled over the rotors): the
first stage's own least-squares criterion, as a two-stage fit chooses its first stage."""

from __future__ import annotations

import numpy as np

from ..errors import UserError
from ..flightlog import FlightLog

LAG_CANDIDATES_S = (0.01, 0.02, 0.03, 0.05, 0.08, 0.12)
DEFAULT_MEMORY_S = 10.0


def command_columns(log: FlightLog) -> np.ndarray:
    """(n, N) motor commands 0..1 from cmd_1..cmd_N, or a one-line error."""
    names = tuple(f"cmd_{i + 1}" for i in range(log.rotor_count))
    commands = log.group(names)
    if commands is None:
        raise UserError(f"--instrument commands needs the columns {', '.join(names)} (motor commands 0..1): "
                        f"the log has none")
    finite = commands[np.isfinite(commands)]
    if finite.size == 0:
        raise UserError("--instrument commands: the cmd_* columns hold no finite value")
    if finite.min() < 0.0 or finite.max() > 1.0:
        raise UserError(f"--instrument commands: cmd_* outside 0..1 ({finite.min():.3g}..{finite.max():.3g}); "
                        f"the commands must be normalised")
    return commands


def lagged(commands: np.ndarray, t: np.ndarray, lag_s: float) -> np.ndarray:
    """The first stage's lag as the firmware runs it: the previous command held over each interval,
    starting at the first logged command's steady state (an events log's first row may be another
    stream's)."""
    out = np.empty_like(commands)
    logged = np.flatnonzero(np.all(np.isfinite(commands), axis=1))
    state = commands[logged[0]].copy() if logged.size else np.zeros(commands.shape[1])
    held = state.copy()
    out[0] = state
    for k in range(1, len(commands)):
        decay = np.exp(-(t[k] - t[k - 1]) / lag_s)
        state = held + (state - held) * decay
        out[k] = state
        row = commands[k]
        held = np.where(np.isfinite(row), row, held)
    return out


def first_stage_residual(log: FlightLog, commands: np.ndarray, mask: np.ndarray, lag_s: float) -> float:
    """Pooled residual share of the increments of Omega^2 after their fit on the increments of
    z and z^2 (z = lagged command - 1/2), the first stage's own criterion (propid_instrument.c)."""
    s = lagged(commands, log.t, lag_s)
    residual, total = 0.0, 0.0
    for i in range(log.rotor_count):
        y = log.rotor_speed[:, i] ** 2
        ok = mask & np.isfinite(y) & np.isfinite(s[:, i])
        rows = np.flatnonzero(ok)
        if rows.size < 10:
            continue
        z = s[rows, i] - 0.5
        design = np.column_stack([np.diff(z), np.diff(z * z)])
        target = np.diff(y[rows])
        theta, *_ = np.linalg.lstsq(design, target, rcond=None)
        residual += float(np.sum((target - design @ theta) ** 2))
        total += float(np.sum(target ** 2))
    return residual / total if total > 0 else float("nan")


def choose_lag(log: FlightLog, commands: np.ndarray, mask: np.ndarray) -> dict:
    shares = {lag: first_stage_residual(log, commands, mask, lag) for lag in LAG_CANDIDATES_S}
    finite = {k: v for k, v in shares.items() if np.isfinite(v)}
    if not finite:
        raise UserError("--instrument commands: no rows with both commands and rotor speeds to fit the first stage")
    lag = min(finite, key=finite.get)
    return {"rule": "least first-stage residual of the increments", "lag_s": lag,
            "residual_share": {f"{k:g}": round(v, 4) for k, v in shares.items()}}


def resolve_instrument(log: FlightLog, mask: np.ndarray, options, config_fields: dict,
                       notes: dict) -> np.ndarray | None:
    """--instrument / --command-lag / --command-memory / --command-min-f into the filter's configuration and the
    replay's notes; the (n, N) float32 commands to push, or None with the instrument off."""
    if options.instrument == "off":
        return None
    if options.instrument != "commands":
        raise UserError(f"--instrument {options.instrument!r}: give off or commands")
    commands = np.ascontiguousarray(command_columns(log), dtype=np.float32)
    if options.command_lag == "auto":
        lag_info = choose_lag(log, commands.astype(float), mask)
    else:
        lag = float(options.command_lag)
        if not (np.isfinite(lag) and 1.0e-4 <= lag <= 1.0):
            raise UserError(f"--command-lag {options.command_lag!r}: give 0.0001..1 s or auto")
        lag_info = {"rule": "given", "lag_s": lag}
    memory = DEFAULT_MEMORY_S if options.command_memory is None else float(options.command_memory)
    if not (np.isfinite(memory) and 0.01 <= memory <= 1.0e4):
        raise UserError(f"--command-memory {options.command_memory!r}: give 0.01..10000 s")
    config_fields["motor_command_instrument"] = 1
    config_fields["motor_command_lag"] = float(lag_info["lag_s"])
    min_f = float(options.command_min_f)
    if not (np.isfinite(min_f) and 0.0 <= min_f <= 1.0e6):
        raise UserError(f"--command-min-f {options.command_min_f!r}: give 0..1e6 (0: no guard)")
    config_fields["motor_command_memory"] = memory
    config_fields["motor_command_min_f"] = min_f
    notes["instrument"] = dict(lag_info, memory_s=memory, min_f=min_f)
    return commands
