"""The regression design: per axis, the measured response and the columns of the
base model and of every candidate effect, band-passed per flight segment and
stacked over flights; rows carry their time block and flight.

Base model (the filter's own model, docs/gap.md):
    roll   = sum_i kf_i y_i Omega_i^2        pitch = -sum_i kf_i x_i Omega_i^2
    yaw    = sum_i km_i s_i Omega_i^2        thrust (m acc_z) = sum_i kf_i Omega_i^2
one set of per-rotor kf_i shared by thrust and torques. Torque axes are band-passed
(slow disturbance = nuisance), thrust is low-passed only (no constant: gravity is not
in the body-z specific force and nothing may absorb it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from propid.gap.effects import AXES, EFFECTS, Context, Effect
from propid.gap.prep import Flight

TORQUE_AXES = ("roll", "pitch", "yaw")


@dataclass
class Design:
    axes: list[str]
    names: list[str]  # column names
    groups: dict[str, list[int]]  # "base" / effect id -> column indices
    y: dict[str, np.ndarray]  # axis -> (n,)
    x: dict[str, np.ndarray]  # axis -> (n, P), columns scaled to unit RMS
    scale: np.ndarray  # (P,) physical column = scaled column * scale
    block: np.ndarray  # (n,) global block index
    flight: np.ndarray  # (n,) flight index
    block_flight: np.ndarray  # (B,) flight of each block
    time: np.ndarray  # (n,) time within its flight [s]
    extra: dict = field(default_factory=dict)
    fold_group: np.ndarray | None = None  # (B,) block of which each block is a piece (folds keep pieces together)

    @property
    def n_blocks(self) -> int:
        return int(self.block_flight.shape[0])


def base_columns(f: Flight, positions: np.ndarray, signs: np.ndarray, speed: np.ndarray | None = None) -> dict:
    """Raw base columns per axis: kf_1..N then km_1..N."""
    u = (f.speed if speed is None else speed) ** 2
    n, count = u.shape
    zero = np.zeros((n, count))
    return {
        "roll": np.column_stack([u * positions[:, 1][None, :], zero]),
        "pitch": np.column_stack([-u * positions[:, 0][None, :], zero]),
        "yaw": np.column_stack([zero, u * signs[None, :]]),
        "thrust": np.column_stack([u, zero]),
    }


def responses(f: Flight, mass: float | None) -> dict:
    out = {"roll": f.torque[:, 0], "pitch": f.torque[:, 1], "yaw": f.torque[:, 2]}
    if f.specific_force_z is not None and mass is not None:
        out["thrust"] = mass * f.specific_force_z
    return out


def segment_rows(f: Flight) -> np.ndarray:
    return np.concatenate([np.arange(a, b) for a, b in f.segs])


def build_design(flights: list[Flight], ctx: Context, effects: list[Effect], mass: float | None,
                 with_thrust: bool, scale: np.ndarray | None = None) -> Design:
    """Stack base + effect columns of every flight (filtered per segment). `scale`: use
    another design's column scaling (held-out flights evaluated with its coefficients)."""
    count = ctx.positions.shape[0]
    names = [f"kf_{i + 1}" for i in range(count)] + [f"km_{i + 1}" for i in range(count)]
    groups = {"base": list(range(2 * count))}
    for e in effects:
        start = len(names)
        names += [f"{e.id}.{p}" for p in e.params]
        groups[e.id] = list(range(start, len(names)))
    axes = [a for a in AXES if a != "thrust" or with_thrust]
    ys = {a: [] for a in axes}
    xs = {a: [] for a in axes}
    blocks, flight_idx, times, block_flight = [], [], [], []
    signals = {"gyro": [], "speed_h": [], "height": [], "throttle_rate": []}
    block_offset = 0
    for fi, f in enumerate(flights):
        rows = segment_rows(f)
        cols = base_columns(f, ctx.positions, ctx.yaw_signs)
        per_effect = [e.build(f, ctx) for e in effects]
        resp = responses(f, mass)
        for a in axes:
            parts = [cols[a]]
            for e, built in zip(effects, per_effect):
                parts.append(built.get(a, np.zeros((len(f.t), len(e.params)))))
            lowpass_only = a == "thrust"
            # torque axes: every column not itself a central difference gets the measured
            # torque's difference response (prep.difference_response)
            given = [not lowpass_only] + [not lowpass_only and not e.differenced for e in effects]
            xs[a].append(np.column_stack([f.filtered(part, lowpass_only, response=g)
                                          for part, g in zip(parts, given)])[rows])
            ys[a].append(f.filtered(resp[a], lowpass_only)[rows])
        block_of_row = np.full(len(f.t), -1)
        for k, (s, e) in enumerate(f.blocks):
            block_of_row[s:e] = block_offset + k
        blocks.append(block_of_row[rows])
        flight_idx.append(np.full(rows.size, fi))
        times.append(f.t[rows])
        signals["gyro"].append(f.gyro[rows])
        signals["speed_h"].append(np.hypot(f.body_velocity[rows, 0], f.body_velocity[rows, 1])
                                  if f.body_velocity is not None else np.full(rows.size, np.nan))
        signals["height"].append(f.height[rows] if f.height is not None else np.full(rows.size, np.nan))
        total = (f.speed**2).sum(axis=1)
        signals["throttle_rate"].append((np.gradient(total, f.t) / np.maximum(np.median(total[rows]), 1e-9))[rows])
        block_flight += [fi] * len(f.blocks)
        block_offset += len(f.blocks)
    x = {a: np.concatenate(xs[a]) for a in axes}
    y = {a: np.concatenate(ys[a]) for a in axes}
    if scale is None:
        ss = sum(np.sum(x[a] ** 2, axis=0) for a in axes)
        n_rows = sum(x[a].shape[0] for a in axes)
        scale = np.sqrt(ss / max(n_rows, 1))
        scale[scale == 0] = 1.0
    for a in axes:
        x[a] = x[a] / scale[None, :]
    return Design(axes=axes, names=names, groups=groups, y=y, x=x, scale=scale,
                  block=np.concatenate(blocks), flight=np.concatenate(flight_idx),
                  block_flight=np.array(block_flight, dtype=int), time=np.concatenate(times),
                  extra={k: np.concatenate(v) for k, v in signals.items()})
