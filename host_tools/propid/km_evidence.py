"""How much a flight tells about the rotors' drag coefficients km (`propid real-data --km-evidence`,
docs/real-data.md "km: what the information allows").

Every km_i acts on one axis, yaw: Jzz domega_z/dt = sum_i s_i km_i u_i (+ the rotors' reaction and the small
gyroscopic term), u_i = Omega_i^2, s_i the yaw signs. A controller moves the u_i along four input channels, the
patterns c of yaw (s), collective (1), roll (y_i) and pitch (-x_i); a channel of amplitude a changes the yaw
torque by a sum_i s_i c_i km_i, so each channel measures one km combination, w_c = s*c / sum|c| (relative to the
nominal): yaw -> the mean km, collective -> the yaw-sign-weighted sum, roll and pitch -> two differences. A
rotor's km needs all of them (for a quad X, var km_i = the sum of the four combinations' variances).

Per log, over its flying rows, with the rotor stream aligned by the replay's per-log rule and the noise of the
replay's `--noise auto` rule (nothing else is chosen):
- the yaw regression of one-step rate increments on the per-rotor km regressors (the filter's step: trapezoid
  input, the gyroscopic term removed), least squares; its coefficient std under a white residual, and under the
  residual as it is (Newey-West, NW_WINDOW_S: the yaw residual is coloured); with and without the vehicle file's
  rotor-inertia reaction as a known term;
- the bound of the filter's own model (its pooled rate process noise, prior, km walk 0 and the library walk):
  the Kalman recursion of the km states with the regressors of the log; the filter's final km std equals it when
  the filter is at its information limit;
- the excitation of each channel (rms of its amplitude relative to the mean u) and the yaw acceleration its
  km combination drives at the nominal km;
- the flight time the same manoeuvres would need for every rotor's km to 5 % (one std) and for the filter's 3-std
  claim (5 % / 3), constant km, by the residual as it is: duration x (worst rotor std / target)^2.
"""

from __future__ import annotations

import statistics

import numpy as np

from propid.cfilter import DEFAULT_TUNING
from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.signals import bartlett_long_run_covariance

CHANNELS = ("yaw", "collective", "roll", "pitch")
NW_WINDOW_S = 0.5  # Newey-West window: beyond the yaw residual's correlation (lags of a few samples)
# The library's defaults, read from the one Python mirror of propid_config_default() (checked against the C
# library by tests/host_tools/test_reference_vs_c.py): the per-rotor target (converged_rel_std) ...
TARGET_REL_STD = float(DEFAULT_TUNING["converged_rel_std"])
CLAIM_SIGMAS = 3.0  # ... and the filter's claim: 3 std below it (docs/reliability.md "Converged claims")
LIBRARY_WALK = float(DEFAULT_TUNING["drag_coeff_rel_walk"])  # [1/sqrt(s)]
PRIOR_REL_STD = float(DEFAULT_TUNING["drag_coeff_rel_std0"])


def channel_patterns(vehicle: Vehicle) -> np.ndarray:
    """(4, N) input patterns of the yaw, collective, roll and pitch channels."""
    positions = np.asarray(vehicle.positions, dtype=float)
    signs = np.asarray(vehicle.yaw_signs, dtype=float)
    return np.array([signs, np.ones(signs.size), positions[:, 1], -positions[:, 0]])


def combination_weights(vehicle: Vehicle) -> np.ndarray:
    """(4, N) weights of the km_rel combination each channel measures: s * c / sum|c| (a mean for the yaw
    channel: its relative std is the mean km's)."""
    patterns = channel_patterns(vehicle)
    signs = np.asarray(vehicle.yaw_signs, dtype=float)
    scale = np.sum(np.abs(patterns), axis=1, keepdims=True)
    return patterns * signs[None, :] / np.where(scale > 0, scale, 1.0)


def combination_std(covariance: np.ndarray, vehicle: Vehicle) -> dict:
    """Std of each channel's km combination from a covariance of km_rel (N x N, relative to the nominal)."""
    weights = combination_weights(vehicle)
    variance = np.einsum("ci,ij,cj->c", weights, np.asarray(covariance, dtype=float), weights)
    return {name: float(np.sqrt(max(v, 0.0))) for name, v in zip(CHANNELS, variance)}


def newey_west(design: np.ndarray, residual: np.ndarray, lags: int) -> np.ndarray:
    """Covariance of least-squares coefficients with an autocorrelated residual (Bartlett weights over `lags`)."""
    inverse = np.linalg.inv(design.T @ design)
    return inverse @ bartlett_long_run_covariance(design * residual[:, None], lags) @ inverse


def model_bound(regressors: np.ndarray, step_variance: np.ndarray, walk: float, dt: float,
                prior: float = PRIOR_REL_STD) -> np.ndarray:
    """Final covariance of km_rel in the filter's model along the regressors: prior, random walk, one scalar yaw
    measurement of the rate increment per step with the given variance (the rate states are reset by the gyro
    almost completely each step, docs/real-data.md, so the increments carry the information)."""
    n = regressors.shape[1]
    cov = np.eye(n) * prior**2
    walk_var = np.eye(n) * walk**2 * dt
    for row, variance in zip(regressors, step_variance):
        cov += walk_var
        gain = cov @ row
        cov -= np.outer(gain, gain) / (row @ gain + variance)
    return cov


def yaw_regression(log: FlightLog, vehicle: Vehicle, lag: int) -> dict:
    """The filter's yaw step on the flying rows: increments y_k = w_z[k] - w_z[k-1] minus the gyroscopic term,
    per-rotor km_rel regressors dt km_nominal / Jzz s_i ubar_i (ubar the trapezoid of u[k-lag], u[k-lag-1]),
    the rotors' reaction s_i J_r,i / Jzz (Omega_i[k-lag] - Omega_i[k-lag-1]) when the file has a rotor inertia."""
    from propid.realdata_checks import flying_mask
    from propid.replay.thrust_aero import cleaned_rotor_speeds
    from propid.signals import median_dt

    if vehicle.inertia is None or vehicle.km_nominal is None:
        raise UserError("--km-evidence needs the vehicle's inertia and km_nominal")
    inertia = np.asarray(vehicle.inertia, dtype=float)
    inertia = np.diag(inertia) if inertia.ndim == 1 else inertia
    if np.any(inertia - np.diag(np.diag(inertia))):
        raise UserError("--km-evidence: the yaw regression assumes a diagonal inertia")
    jxx, jyy, jzz = np.diag(inertia)
    signs = np.asarray(vehicle.yaw_signs, dtype=float)
    km_nominal = np.broadcast_to(np.asarray(vehicle.km_nominal, dtype=float), signs.shape)
    dt = median_dt(log.t)
    speeds = np.roll(cleaned_rotor_speeds(log), lag, axis=0)  # speeds[k] = the sample that acts at step k
    u = speeds**2
    mask = flying_mask(log)
    k = np.arange(lag + 1, len(log))
    gyro = log.gyro
    ok = mask[k] & mask[k - 1] & np.all(np.isfinite(gyro[k]), axis=1) & np.all(np.isfinite(gyro[k - 1]), axis=1)
    steps = log.t[k] - log.t[k - 1]
    ok &= (steps > 0.5 * dt) & (steps < 1.5 * dt) & np.all(np.isfinite(u[k]) & np.isfinite(u[k - 1]), axis=1)
    k, steps = k[ok], steps[ok]
    if k.size < 100:
        raise UserError(f"{log.path}: fewer than 100 flying yaw steps")
    mid = 0.5 * (gyro[k] + gyro[k - 1])
    increment = gyro[k, 2] - gyro[k - 1, 2] - steps * (jxx - jyy) / jzz * mid[:, 0] * mid[:, 1]
    ubar = 0.5 * (u[k] + u[k - 1])
    regressors = steps[:, None] * (km_nominal * signs / jzz)[None, :] * ubar
    rotor_inertia = vehicle.rotor_inertias
    reaction = None
    if rotor_inertia:
        reaction = (signs * np.asarray(rotor_inertia, dtype=float) / jzz)[None, :] * (speeds[k] - speeds[k - 1])
        reaction = reaction.sum(axis=1)
    return {"increment": increment, "regressors": regressors, "reaction": reaction, "ubar": ubar, "dt": dt,
            "steps": steps, "km_yaw_gain": km_nominal * signs / jzz}


def _fit(regressors: np.ndarray, response: np.ndarray, lags: int) -> dict:
    coeffs, *_ = np.linalg.lstsq(regressors, response, rcond=None)
    residual = response - regressors @ coeffs
    white = float(np.var(residual)) * np.linalg.inv(regressors.T @ regressors)
    coloured = newey_west(regressors, residual, lags)
    return {"km_rel": coeffs, "residual": residual, "white": white, "coloured": coloured}


def _walk_key(walk: float) -> str:
    """The JSON key of the filter-model bound with this km walk ('walk_0', 'walk_0.02')."""
    return f"walk_{walk:g}"


def km_evidence(log: FlightLog, vehicle: Vehicle) -> dict:
    """The entry of one log (see the module text)."""
    from propid.replay.alignment import estimate_esc_delay
    from propid.replay.noise import estimate_noise
    from propid.realdata_checks import flying_mask
    from propid.signals import median_dt

    mask = flying_mask(log)
    dt = median_dt(log.t)
    lag = max(0, int(round(-estimate_esc_delay(log, vehicle, mask) / dt)))  # rotor samples held by the filter
    data = yaw_regression(log, vehicle, lag)
    inertia = np.asarray(vehicle.inertia, dtype=float)
    noise = estimate_noise(log, np.diag(inertia) if inertia.ndim == 1 else inertia,
                           np.asarray(vehicle.positions), np.asarray(vehicle.yaw_signs, dtype=float), mask)
    if not noise:
        raise UserError(f"{log.path}: too few rows to measure the noise")
    regressors, steps = data["regressors"], data["steps"]
    lags = max(1, int(round(NW_WINDOW_S / dt)))
    fits = {"without_rotor_inertia": _fit(regressors, data["increment"], lags)}
    if data["reaction"] is not None:
        fits["with_rotor_inertia"] = _fit(regressors, data["increment"] - data["reaction"], lags)
    gyro_var = noise["gyro_noise_density"] ** 2 * noise["gyro_sample_rate_hz"]
    filter_step_var = noise["rate_process_noise"] ** 2 * steps + 2.0 * gyro_var
    bounds = {_walk_key(walk): model_bound(regressors, filter_step_var, walk, dt) for walk in (0.0, LIBRARY_WALK)}
    duration = float(steps.sum())

    def stds(cov):
        return {"rotor": [float(v) for v in np.sqrt(np.clip(np.diag(cov), 0.0, None))],
                "combination": combination_std(cov, vehicle)}

    patterns = channel_patterns(vehicle)
    amplitude = data["ubar"] @ patterns.T / np.sum(np.abs(patterns), axis=1)  # mean of +-u per channel
    mean_u = float(np.mean(data["ubar"]))
    weights = combination_weights(vehicle)
    # Yaw acceleration per unit amplitude of a channel and unit change of its combination (u = mean + a c with
    # a = u.c / sum|c|, i.e. the mean of +-u for a +-1 pattern): sum_i |c_i| km_nom_i / Jzz x sum|c| / c.c.
    gain = np.abs(data["km_yaw_gain"])
    drive = (np.abs(patterns) @ gain) * np.sum(np.abs(patterns), axis=1) / np.sum(patterns**2, axis=1)
    entry = {
        "duration_s": duration, "steps": int(steps.size), "rotor_lag_samples": lag,
        "rate_process_noise": noise["rate_process_noise"], "gyro_noise_density": noise["gyro_noise_density"],
        "excitation_rel": {c: float(np.std(amplitude[:, j]) / mean_u) for j, c in enumerate(CHANNELS)},
        "yaw_drive_rms": {c: float(drive[j] * np.std(amplitude[:, j])) for j, c in enumerate(CHANNELS)},
        "combination_weights": weights.tolist(),
        "filter_model": {name: stds(cov) for name, cov in bounds.items()},
        "fits": {},
    }
    for name, fit in fits.items():
        residual = fit["residual"]
        entry["fits"][name] = {
            "km_rel": [float(v) for v in fit["km_rel"]],
            "yaw_residual_density": float(np.std(residual) / np.sqrt(dt)),
            "residual_autocorrelation": {str(L): float(np.corrcoef(residual[:-L], residual[L:])[0, 1])
                                         for L in (1, 2, 3, 5, 10)},
            "white": stds(fit["white"]), "as_is": stds(fit["coloured"]),
        }
    worst = max(entry["fits"]["without_rotor_inertia"]["as_is"]["rotor"])
    entry["seconds_for_every_rotor"] = {"one_std_5pct": duration * (worst / TARGET_REL_STD) ** 2,
                                        "claim_3std_5pct": duration * (worst * CLAIM_SIGMAS / TARGET_REL_STD) ** 2}
    return entry


def km_evidence_all(logs: dict[str, FlightLog], vehicle: Vehicle) -> dict:
    return {name: km_evidence(log, vehicle) for name, log in logs.items()}


def render_km_evidence(entries: dict) -> str:
    """Per run: excitation, the per-rotor and mean-km stds (filter model, white, as is), the time needed."""
    target = f"{100 * TARGET_REL_STD:g}"
    lines = ["| run | s | yaw channel rms [% of mean u] | its yaw accel. [rad/s^2] | LS km / nominal, rotors "
             f"| yaw residual [rad/s^2/sqrt(Hz)] (filter q) | per-rotor std: filter model walk {LIBRARY_WALK:g} / walk 0 "
             f"/ white / as is | mean-km std: same | sign-weighted km std as is | s for every rotor at {target} %: one std "
             f"/ {CLAIM_SIGMAS:g} std |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, e in entries.items():
        fit = e["fits"]["without_rotor_inertia"]
        model = e["filter_model"]
        library, frozen = model[_walk_key(LIBRARY_WALK)], model[_walk_key(0.0)]
        rotor = [max(library["rotor"]), max(frozen["rotor"]), max(fit["white"]["rotor"]), max(fit["as_is"]["rotor"])]
        mean = [library["combination"]["yaw"], frozen["combination"]["yaw"],
                fit["white"]["combination"]["yaw"], fit["as_is"]["combination"]["yaw"]]
        lines.append(
            f"| {name} | {e['duration_s']:.0f} | {100 * e['excitation_rel']['yaw']:.1f} "
            f"| {e['yaw_drive_rms']['yaw']:.2f} | {' '.join(f'{v:.2f}' for v in fit['km_rel'])} "
            f"| {fit['yaw_residual_density']:.2f} ({e['rate_process_noise']:.2f}) "
            f"| {' / '.join(f'{100 * v:.0f}' for v in rotor)} % | {' / '.join(f'{100 * v:.0f}' for v in mean)} % "
            f"| {100 * fit['as_is']['combination']['collective']:.1f} % "
            f"| {e['seconds_for_every_rotor']['one_std_5pct']:.0f} / {e['seconds_for_every_rotor']['claim_3std_5pct']:.0f} |")
    per_rotor = [max(e["fits"]["without_rotor_inertia"]["as_is"]["rotor"]) for e in entries.values()]
    lines += ["", f"worst rotor's std as is: median {100 * statistics.median(per_rotor):.0f} % over "
              f"{len(per_rotor)} runs; runs with every rotor's std as is below {target} %: "
              f"{sum(v < TARGET_REL_STD for v in per_rotor)}, below {target} % / {CLAIM_SIGMAS:g}: "
              f"{sum(v < TARGET_REL_STD / CLAIM_SIGMAS for v in per_rotor)}"]
    return "\n".join(lines) + "\n"
