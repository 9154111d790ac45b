"""The paper's experiment: trajectories x controller modes x randomized trials of propid_sitl.

Trial k of every (trajectory, mode) uses the seed ``base_seed + k``: the same true
coefficients (nominal x U(1-s, 1+s) per rotor, drawn by the simulator from the seed)
and the same gyro biases in the three modes, so the modes are compared on identical
vehicles. The filter's prior and the Incorrect controller start from the nominal
catalogue values (propid_sitl's ``--incorrect-source nominal``); the filter's prior
standard deviations are those of the truth distribution, and its noise settings are
the campaign's (CampaignConfig, documented in docs/results.md).

Each flight is a propid_sitl subprocess writing a CSV log; a pool of workers (2 by
default: this machine has two cores) runs them, computes the flight's metrics
(propid.table1) and deletes the log unless asked to keep it.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field
from pathlib import Path

from propid import crlb, table1
from propid.errors import UserError
from propid.flightlog import read_vehicle
from propid.outputs import make_directory, write_text

REPO_ROOT = Path(__file__).resolve().parents[2]
EXIT_DIVERGED = 3  # propid_sitl's exit code for a flight it stopped


def default_build_dir() -> Path:
    return Path(os.environ.get("PROPID_BUILD_DIR", REPO_ROOT / "build" / "host"))


def locate_sitl(explicit: str | None = None) -> Path:
    """propid_sitl: explicit path, else $PROPID_BUILD_DIR/sitl/propid_sitl."""
    path = Path(explicit) if explicit else default_build_dir() / "sitl" / "propid_sitl"
    if not path.is_file() or not os.access(path, os.X_OK):
        raise UserError(f"propid_sitl not found at {path} (build it with `make host`, "
                        "or set PROPID_BUILD_DIR / --sitl)")
    return path.resolve()


@dataclass
class CampaignConfig:
    out_dir: Path
    sitl: Path
    trajectories: tuple[str, ...] = table1.TRAJECTORIES
    modes: tuple[str, ...] = table1.MODES
    trials: int = 10
    base_seed: int = 1
    duration_s: float = 10.0
    vehicle: str = "crazyflie-plus"
    coeff_spread: float = 0.2        # truth = nominal x U(1 - s, 1 + s)
    gyro_bias_max: float = 0.0174533  # truth bias per axis U(-b, b) [rad/s] (1 deg/s)
    paper_sensors: bool = True        # --paper: 500 Hz gyro, exact rotor speeds
    start_at_rest: bool = True        # the paper's simulator starts the vehicle at rest
    # Time of the first rotor-speed report (propid_sitl --esc-phase); None = the
    # simulator's default (with --paper: synchronous with the gyro, as in the paper).
    esc_phase_s: float | None = None
    # Filter configuration the SITL gives the EKF (docs/results.md): priors equal to
    # the truth distribution's std, no random walks (the truth is constant, as in the
    # paper's eq. 7), a small rate process noise and a 0.01 rad/s body-rate prior
    # (rate_std0), both picked by the rule of docs/results.md on seeds 101-120, not
    # the reported 1-10 (re-tuned for the Heun / covariance-health filter). A tight
    # "at rest" rate prior was measured not to help (docs/results.md).
    filter_rate_noise: float | None = 0.0004
    prior_rate_std: float | None = 0.01
    filter_coeff_walk: float | None = 0.0
    filter_bias_walk: float | None = 0.0
    priors_from_truth: bool = True
    # Cramér-Rao bound along each flight (propid.crlb): its times next to the filter's.
    cramer_rao: bool = True
    extra_args: list[str] = field(default_factory=list)  # appended to every propid_sitl call
    workers: int = 2
    keep_logs: bool = False
    max_position_error: float = 1.0   # stability bound [m]
    timeout_s: float = 600.0


@dataclass
class Job:
    trajectory: str
    mode: str
    trial: int
    seed: int


# The filter library's default priors (firmware/src/propid_config.c), used when the
# campaign leaves them to the library (--library-filter-config).
LIBRARY_COEFF_REL_STD0 = 0.3
LIBRARY_GYRO_BIAS_STD0 = 0.05
LIBRARY_RATE_STD0 = 1.0
LIBRARY_RATE_PROCESS_NOISE = 0.2
LIBRARY_COEFF_WALK = 0.02
LIBRARY_BIAS_WALK = 1.0e-4
# propid_sitl's gyro noise density (BMI088, sitl/imu.c), which it also gives the
# filter; a --gyro-noise in the extra SITL arguments overrides it.
SITL_GYRO_NOISE_DENSITY = math.radians(0.014)


def _extra_option(args: list[str], name: str) -> str | None:
    for i, arg in enumerate(args):
        if arg == name and i + 1 < len(args):
            return args[i + 1]
        if arg.startswith(name + "="):
            return arg.split("=", 1)[1]
    return None


def bound_config(config: CampaignConfig) -> crlb.BoundConfig:
    """The filter's own model, prior and noise as the SITL configures it (for the bound)."""
    coeff_std, bias_std = filter_priors(config)
    noise = _extra_option(config.extra_args, "--gyro-noise")

    def pick(value, library):
        return library if value is None else value
    return crlb.BoundConfig(
        gyro_noise_density=float(noise) if noise is not None else SITL_GYRO_NOISE_DENSITY,
        rate_process_noise=pick(config.filter_rate_noise, LIBRARY_RATE_PROCESS_NOISE),
        rate_std0=pick(config.prior_rate_std, LIBRARY_RATE_STD0),
        coeff_rel_std0=coeff_std, bias_std0=bias_std,
        coeff_walk=pick(config.filter_coeff_walk, LIBRARY_COEFF_WALK),
        bias_walk=pick(config.filter_bias_walk, LIBRARY_BIAS_WALK))


def filter_priors(config: CampaignConfig) -> tuple[float, float]:
    """(coefficient relative std, gyro bias std [rad/s]) the SITL's filter starts with,
    exactly as passed on its command line."""
    if not config.priors_from_truth:
        return LIBRARY_COEFF_REL_STD0, LIBRARY_GYRO_BIAS_STD0
    coeff_std = float(f"{config.coeff_spread / math.sqrt(3.0):.6g}")
    bias_std = float(f"{config.gyro_bias_max / math.sqrt(3.0):.6g}")
    return coeff_std, bias_std


def convergence_spec(config: CampaignConfig) -> "table1.ConvergenceSpec":
    """0.1 x the filter's prior std (docs/results.md, Definitions)."""
    return table1.ConvergenceSpec.from_prior_std(*filter_priors(config))


def sitl_command(config: CampaignConfig, job: Job, log_path: Path) -> list[str]:
    cmd = [str(config.sitl)]
    if config.paper_sensors:
        cmd.append("--paper")
    cmd += [
        "--vehicle", config.vehicle,
        "--trajectory", job.trajectory,
        "--mode", job.mode,
        "--seed", str(job.seed),
        "--duration", repr(config.duration_s),
        "--coeff-spread", repr(config.coeff_spread),
        "--gyro-bias-max", repr(config.gyro_bias_max),
        "--incorrect-source", "nominal",
        "--log", str(log_path),
        "--quiet",
    ]
    if config.start_at_rest:
        cmd.append("--start-at-rest")
    if config.esc_phase_s is not None:
        cmd += ["--esc-phase", repr(config.esc_phase_s)]
    if config.priors_from_truth:
        coeff_std, bias_std = filter_priors(config)
        cmd += ["--prior-kf-std", f"{coeff_std:.6g}", "--prior-km-std", f"{coeff_std:.6g}",
                "--prior-bias-std", f"{bias_std:.6g}"]
    for option, value in (("--prior-rate-std", config.prior_rate_std),
                          ("--filter-rate-noise", config.filter_rate_noise),
                          ("--filter-coeff-walk", config.filter_coeff_walk),
                          ("--filter-bias-walk", config.filter_bias_walk)):
        if value is not None:
            cmd += [option, repr(value)]
    return cmd + list(config.extra_args)


def run_job(config: CampaignConfig, job: Job) -> dict:
    """Fly one trial and return its metrics (runs in a worker process)."""
    log_dir = config.out_dir / "logs"
    log_dir.mkdir(parents=True, exist_ok=True)
    log_path = log_dir / f"{job.trajectory}_{job.mode}_{job.trial:02d}.csv"
    vehicle_path = log_path.with_suffix(".vehicle.json")
    cmd = sitl_command(config, job, log_path)
    record = {"trajectory": job.trajectory, "mode": job.mode, "trial": job.trial,
              "seed": job.seed}
    start = time.monotonic()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=config.timeout_s,
                              check=False)
    except subprocess.TimeoutExpired:
        record.update(stable=False, error=f"timed out after {config.timeout_s:g} s")
        return record
    except OSError as exc:  # e.g. the binary is being rebuilt right now
        record.update(stable=False, error=f"cannot run {cmd[0]}: {exc.strerror}")
        return record
    record["wall_s"] = round(time.monotonic() - start, 3)
    record["exit_code"] = proc.returncode
    if proc.returncode not in (0, EXIT_DIVERGED) or not log_path.is_file():
        tail = (proc.stderr or "").strip().splitlines()[-3:]
        record.update(stable=False, error=f"propid_sitl exit {proc.returncode}: "
                      + " | ".join(tail), command=" ".join(cmd))
        return record
    try:
        columns = table1.read_log_columns(log_path)
        kf_nom, km_nom = table1.read_nominal_coefficients(vehicle_path, table1.rotor_count(columns))
        spec = convergence_spec(config)
        record.update(table1.trial_metrics(
            columns, kf_nom, km_nom, spec, duration_s=config.duration_s,
            diverged=proc.returncode == EXIT_DIVERGED,
            max_position_error=config.max_position_error, where=str(log_path)))
        if config.cramer_rao:
            try:  # the bound is context: a flight it cannot be computed for stays a flight
                record.update(crlb.bound_times_for_log(columns, read_vehicle(vehicle_path),
                                                       bound_config(config)))
            except UserError as exc:
                record["bound_error"] = str(exc)
    except UserError as exc:
        record.update(stable=False, error=str(exc))
    finally:
        if not config.keep_logs:
            for path in (log_path, vehicle_path):
                path.unlink(missing_ok=True)
    return record


def jobs_for(config: CampaignConfig) -> list[Job]:
    return [Job(traj, mode, trial, config.base_seed + trial)
            for trial in range(config.trials)
            for traj in config.trajectories
            for mode in config.modes]


def run_campaign(config: CampaignConfig, progress: bool = True) -> dict:
    """Run every flight, aggregate, write table1.json and table1.md into out_dir."""
    return run_campaigns([config], progress=progress)[0]


def run_campaigns(configs: list[CampaignConfig], progress: bool = True,
                  desc: str = "campaign") -> list[dict]:
    """Several campaigns' flights in ONE pool of workers (the cores stay busy across
    campaigns) under one progress bar; then each campaign's table1.json and
    table1.md into its own out_dir. Returns the tables in the order given."""
    from tqdm import tqdm

    for config in configs:
        make_directory(config.out_dir)
    work = [(index, job) for index, config in enumerate(configs) for job in jobs_for(config)]
    records: list[list[dict]] = [[] for _ in configs]
    bar = tqdm(total=len(work), desc=desc, unit="flight", disable=not progress, mininterval=0.5,
               file=sys.stderr)
    workers = max(1, max((config.workers for config in configs), default=1))
    pool = ProcessPoolExecutor(max_workers=workers)
    try:
        pending = {pool.submit(run_job, configs[index], job): index for index, job in work}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                index = pending.pop(future)
                record = future.result()
                records[index].append(record)
                where = f"{configs[index].vehicle} " if len(configs) > 1 else ""
                bar.set_postfix_str(f"{where}{record['trajectory']}/{record['mode']}/{record['trial']}")
                bar.update(1)
    except KeyboardInterrupt:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    finally:
        bar.close()
    pool.shutdown(wait=True)

    tables = []
    for config, config_records in zip(configs, records):
        config_records.sort(key=lambda r: (r["trajectory"], r["mode"], r["trial"]))
        table = build_table(config, config_records)
        write_outputs(config.out_dir, table)
        tables.append(table)
    return tables


def build_table(config: CampaignConfig, records: list[dict]) -> dict:
    table: dict = {}
    for traj in config.trajectories:
        for mode in config.modes:
            trials = [r for r in records if r["trajectory"] == traj and r["mode"] == mode]
            for r in trials:  # a flight that failed to produce metrics counts as unstable
                r.setdefault("stable", False)
            complete = [r for r in trials if "rmse_x" in r]
            row = table1.aggregate(complete, config.duration_s)
            row["trials"] = len(trials)
            row["stable_pct"] = (100.0 * sum(1 for r in trials if r["stable"]) / len(trials)
                                 if trials else 0.0)
            row["per_trial"] = trials
            table.setdefault(traj, {})[mode] = row
    conditions = asdict(config)
    conditions["out_dir"] = str(config.out_dir)
    conditions["sitl"] = str(config.sitl)
    spec = convergence_spec(config)
    conditions["coeff_threshold_rel"] = spec.coeff_threshold_rel
    conditions["bias_threshold_rad_s"] = spec.bias_threshold
    conditions["command_example"] = " ".join(
        sitl_command(config, Job("lissajous", "filter", 0, config.base_seed), Path("X.csv")))
    table["_conditions"] = conditions
    return table


def write_outputs(out_dir: Path, table: dict) -> None:
    write_text(out_dir / "table1.json", json.dumps(table, indent=1, default=str) + "\n")
    conditions = table.get("_conditions", {})
    header = ("# Table 1 (propid SITL campaign)\n\n"
              f"Vehicle {conditions.get('vehicle')}, {conditions.get('trials')} trials per cell, "
              f"seeds {conditions.get('base_seed')}..."
              f"{conditions.get('base_seed', 0) + conditions.get('trials', 0) - 1}, "
              f"{conditions.get('duration_s')} s flights.\n"
              f"Example flight: `{conditions.get('command_example')}`\n\n")
    write_text(out_dir / "table1.md", header + table1.render_markdown(table) + "\n"
               + table1.render_bound_markdown(table))
