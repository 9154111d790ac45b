"""The filter configuration a replay runs with (propid_config_t fields, SI) and notes on
where each value came from."""

from __future__ import annotations

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.realdata_checks import absurd_speed_limit, check_log, flying_mask
from propid.replay.alignment import gyro_rows_view
from propid.replay.noise import estimate_noise
from propid.replay.options import ReplayOptions
from propid.replay.vehicle_terms import resolve_aero_damping

NOISE_FIELDS = ("gyro_noise_density", "gyro_sample_rate_hz", "rate_process_noise")

def _nominals(vehicle: Vehicle, options: ReplayOptions, log: FlightLog) -> tuple[list[float], list[float], str]:
    n = vehicle.rotor_count
    if options.unit_inertia:
        if options.kf_nominal is not None and options.km_nominal is not None:
            return [options.kf_nominal] * n, [options.km_nominal] * n, "given"
        # Start from the log's own band-limited torque fit (J = 1): a data-driven prior.
        checks = check_log(log, vehicle, bands={"band": (1.0, 10.0)}, unit_inertia=True)
        entry = checks["bands"].get("band")
        if not entry:
            raise UserError("unit-inertia mode: no flying segment to initialise kf/J and km/J from; give --kf-nominal/--km-nominal")
        kf = 0.5 * (entry["roll_kf"]["kf"] + entry["pitch_kf"]["kf"])
        km = entry["yaw_km_rotor_inertia"]["km"]
        if not (kf > 0 and km > 0):
            raise UserError(
                f"unit-inertia mode: the log's torque fit gives kf/J = {kf:.3g}, km/J = {km:.3g}: not positive, "
                "so the vehicle file's geometry or yaw signs disagree with the data; give --kf-nominal/--km-nominal"
            )
        kf = options.kf_nominal if options.kf_nominal is not None else kf
        km = options.km_nominal if options.km_nominal is not None else km
        return [kf] * n, [km] * n, "band-limited least-squares torque fit of this log (1-10 Hz, J = 1)"
    kf = [options.kf_nominal] * n if options.kf_nominal is not None else vehicle.kf_nominal
    km = [options.km_nominal] * n if options.km_nominal is not None else vehicle.km_nominal
    if kf is None or km is None:
        raise UserError(
            f"vehicle file {vehicle.path or vehicle.name}: kf_nominal/km_nominal are null: give --kf-nominal and "
            "--km-nominal (the filter needs a prior mean)"
        )
    return list(kf), list(km), "vehicle file" if options.kf_nominal is None else "given"


def build_config(vehicle: Vehicle, log: FlightLog, options: ReplayOptions) -> tuple[dict, dict]:
    """Filter configuration fields (propid_config_t names, SI) and notes on where they came from."""
    if vehicle.inertia is None and not options.unit_inertia:
        raise UserError(
            f"vehicle file {vehicle.path or vehicle.name}: inertia is null. The filter turns torques into angular "
            "acceleration with J, so without it kf and km cannot be estimated in SI units. Run with --unit-inertia "
            "to estimate kf/J and km/Jzz ratios instead (see docs/real-data.md)"
        )
    inertia = np.eye(3) if options.unit_inertia else np.asarray(vehicle.inertia, dtype=float)
    kf, km, nominal_source = _nominals(vehicle, options, log)
    limit = options.max_rotor_speed or absurd_speed_limit(log.rotor_speed)
    config = {
        "rotor_count": vehicle.rotor_count,
        "positions": vehicle.positions.tolist(),
        "yaw_signs": vehicle.yaw_signs.tolist(),
        "thrust_coeff_nominal": kf,
        "drag_coeff_nominal": km,
        "inertia": inertia.tolist(),
        "max_rotor_speed": float(limit),
    }
    notes = {"nominals": nominal_source, "max_rotor_speed": "given" if options.max_rotor_speed else
             "2x the 99.9th percentile of the log's finite rotor speeds inside a robust fence "
             "(median + 10 x 1.4826 MAD)"}
    if options.noise == "auto":
        rows = gyro_rows_view(log)  # an events log: its gyro rows with the rotor speeds in force
        auto = estimate_noise(rows, inertia, vehicle.positions, vehicle.yaw_signs, flying_mask(rows))
        config.update(auto)
        if auto:
            notes["noise"] = ("auto: gyro noise and unmodelled angular acceleration measured on the log "
                              "(residual of a least-squares fit of the filter's torque model)")
        else:
            notes["noise"] = ("auto requested, but the log has too few flying samples with both neighbours "
                              "(100 needed) to measure the noise: library defaults used")
    else:
        notes["noise"] = "library defaults"
    _optional_terms(vehicle, log, options, config, notes)
    config.update(options.overrides)
    given = [key for key in NOISE_FIELDS if key in options.overrides]
    if given:
        notes["noise"] += "; given on the command line: " + ", ".join(given)
    # Record the values in force, whatever their source, so the JSON says what was used.
    from propid.cfilter import DEFAULT_TUNING

    for key in NOISE_FIELDS:
        config.setdefault(key, DEFAULT_TUNING[key])
    return config, notes


ACCEL_NOISE_FLOOR = 0.05  # [m/s^2]: no accelerometer is trusted beyond this per sample


def resolve_aiding(vehicle: Vehicle, log: FlightLog, options: ReplayOptions) -> str:
    """'gyro' or 'gyro+accel' for this log (--aiding auto: gyro+accel when the log has acc_*
    columns and the vehicle a mass, not in unit-inertia mode)."""
    usable = log.acc is not None and bool(vehicle.mass) and not options.unit_inertia
    if options.aiding == "auto":
        return "gyro+accel" if usable else "gyro"
    if options.aiding == "gyro+accel" and not usable:
        raise UserError("--aiding gyro+accel needs acc_x/acc_y/acc_z columns in the log, a 'mass' in the vehicle "
                        "file, and SI mode (not --unit-inertia)")
    if options.aiding not in ("gyro", "gyro+accel"):
        raise UserError(f"--aiding {options.aiding!r}: choose gyro, gyro+accel or auto")
    return options.aiding


def accel_noise(log: FlightLog, vehicle: Vehicle, mask: np.ndarray) -> float:
    """Per-sample noise of the z specific force by the filter's own model: the residual of the
    least-squares fit acc_z = c sum_i Omega_i^2 + b over the flying rows (robust: the central
    99 % of the residuals), floored at ACCEL_NOISE_FLOOR. Uses no coefficient value."""
    acc_z = log.acc[:, 2]
    u = np.sum(log.rotor_speed ** 2, axis=1)
    ok = mask & np.isfinite(acc_z) & np.isfinite(u)
    if np.sum(ok) < 20:
        return 0.5
    design = np.column_stack([u[ok], np.ones(int(np.sum(ok)))])
    coef, *_ = np.linalg.lstsq(design, acc_z[ok], rcond=None)
    residual = acc_z[ok] - design @ coef
    lo, hi = np.percentile(residual, [0.5, 99.5])
    central = residual[(residual >= lo) & (residual <= hi)]
    return max(float(np.std(central)), ACCEL_NOISE_FLOOR)


def _optional_terms(vehicle: Vehicle, log: FlightLog, options: ReplayOptions, config: dict, notes: dict) -> None:
    """Accelerometer aiding, disturbance-torque states, rotor inertia and aerodynamic damping (docs/math.md
    §7-9, §17)."""
    aiding = resolve_aiding(vehicle, log, options)
    notes["aiding"] = aiding
    if aiding == "gyro+accel":
        config["mass"] = float(vehicle.mass)
        if options.noise in ("auto", "nis"):
            rows = gyro_rows_view(log)
            config["accel_noise_std"] = accel_noise(rows, vehicle, flying_mask(rows))
            notes["accel_noise_std"] = "auto: residual of acc_z = c sum Omega^2 + b on the flying rows"
    if options.torque_scale not in ("auto", "on", "off"):
        raise UserError(f"--torque-scale {options.torque_scale!r}: choose auto, on or off")
    if options.torque_scale == "on" and aiding != "gyro+accel":
        raise UserError("--torque-scale on needs the accelerometer (--aiding gyro+accel): without it the scale "
                        "of the thrust torques and kf cannot be told apart")
    if aiding == "gyro+accel" and options.torque_scale != "off":
        config["torque_scale"] = 1
    notes["torque_scale"] = "estimated" if config.get("torque_scale") else "fixed (the vehicle file's J and arms)"
    if options.disturbance not in ("on", "off"):
        raise UserError(f"--disturbance {options.disturbance!r}: choose on or off")
    if options.disturbance == "on":
        config["disturbance_torque"] = 1
    notes["disturbance"] = options.disturbance
    if options.disturbance_bandwidth is not None:
        bandwidth = options.disturbance_bandwidth
        if options.disturbance != "on":
            raise UserError("--disturbance-bandwidth needs --disturbance on")
        if not np.isfinite(bandwidth) or bandwidth <= 0.0:
            raise UserError(f"--disturbance-bandwidth {bandwidth!r}: give a positive frequency in Hz")
        config["disturbance_bandwidth"] = float(bandwidth)
        notes["disturbance"] = (f"on, bandwidth {bandwidth:g} Hz (given; walk = 2 pi f x the rate process "
                                "noise)")
    elif options.disturbance == "on" and vehicle.loop_bandwidth_hz is not None:
        # The closed loop cancels body torques below its bandwidth (propid gap's
        # closed_loop_cancellation): the states take that band, kf/km learn above it.
        config["disturbance_bandwidth"] = float(vehicle.loop_bandwidth_hz)
        notes["disturbance"] = (f"on, bandwidth {vehicle.loop_bandwidth_hz:g} Hz (the vehicle file's "
                                "loop_bandwidth_hz; walk = 2 pi f x the rate process noise)")
    elif vehicle.loop_bandwidth_hz is not None:
        notes["disturbance"] = (f"off (the vehicle file's loop_bandwidth_hz {vehicle.loop_bandwidth_hz:g} Hz "
                                "is used only with --disturbance on)")
    if options.rotor_inertia not in ("auto", "on", "off"):
        raise UserError(f"--rotor-inertia {options.rotor_inertia!r}: choose auto, on or off")
    inertias = vehicle.rotor_inertias
    if options.rotor_inertia == "on" and not inertias:
        raise UserError("--rotor-inertia on needs 'rotor_inertia' in the vehicle file")
    use = options.rotor_inertia != "off" and inertias and not options.unit_inertia
    if use:
        config["rotor_inertia"] = [float(v) for v in inertias]
    notes["rotor_inertia"] = "vehicle file" if use else "not modelled"
    resolve_aero_damping(vehicle, options, config, notes)

