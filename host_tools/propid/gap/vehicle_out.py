"""The corrected vehicle file: the significant effects' fitted parameters written into
the vehicle JSON where the model can carry them (flight-log v1 extension keys, docs/flightlog.md).

| effect | written as |
|---|---|
| esc_delay | no fixed `esc_delay_s`: the key is left out, so `propid replay` measures the lag per log |
| inertia_error | `inertia` Jxx, Jyy times the least-squares scale (Jzz kept: no independent yaw reference) |
| gyro_scale | `gyro_scale` = file's times the fitted diagonal (the off-diagonal part is reported, not carried) |
| com_offset | rotor positions minus the fitted offset (x, y); `com_offset` = file's + offset |
| aero_damping | `aero_damping` = file's + fitted [dx, dy, dz] |
| rotor_inertia, rotor_gyroscopic | `rotor_inertia` = fitted J_r |
| closed_loop_cancellation | `loop_bandwidth_hz` = the band edge the rule chose (a lower bound when it is the highest candidate) |
Others (rotor_drag, translational_lift, ground_effect, thrust_nonlinearity) have no key:
listed in `not_carried`.

Why the least-squares torque scale: the file is read by the firmware filter, which takes the
logged rotor speeds as its input without an instrument, so it reads the torque gain the way least
squares does (attenuated where the logged speeds carry errors the torque does not share). With
motor commands, inertia_error's `params` carry the instrument's scale (the base fit's, without
that attenuation) and the least-squares one beside it (`*_least_squares`); the file takes the
latter, the estimator class that will read it. Without commands the two are the same number.
Measured in docs/gap.md ("Crazyflie": the file replayed gyro only on held-out runs).

Why no fixed delay: a telemetry lag belongs to a log (its telemetry schedule, its buffers),
not to the vehicle: on one vehicle's logs it differs from run to run, and the filter's delay
buffer wants the lag in the filter's own discretisation (one Euler step per gyro sample,
whole samples), which replay's per-log rule measures (`--esc-delay auto`, its default for a
file without the key). A significant esc_delay says the file's value (none, or the one it
had) is wrong, so the corrected file drops the key; a delay that is not significant leaves
the file's value as it was.
"""

from __future__ import annotations

import copy

import numpy as np

from propid.flightlog import Rotor, Vehicle


def corrected_vehicle(vehicle: Vehicle, effects: list[dict]) -> tuple[Vehicle, dict]:
    out = copy.deepcopy(vehicle)
    applied, not_carried = {}, []
    for e in effects:
        if not e["significant"]:
            continue
        p = e["params"]
        eid = e["id"]
        if eid == "esc_delay":
            out.esc_delay_s = None  # replay's per-log rule (module docstring)
            applied[eid] = {"esc_delay_s": "per log (left out: propid replay --esc-delay auto)",
                            "fitted_delay_s": float((vehicle.esc_delay_s or 0.0) + p["delay_s"])}
        elif eid == "inertia_error":
            # the file is read by the filter, which takes the rotor speeds without an instrument: the torque
            # scale as least squares measures it (attenuation included), not the instrument's (module docstring)
            sx = p.get("inertia_scale_xx_least_squares", p["inertia_scale_xx"])
            sy = p.get("inertia_scale_yy_least_squares", p["inertia_scale_yy"])
            j = np.array(out.inertia, dtype=float)
            j[0, 0] *= sx
            j[1, 1] *= sy
            out.inertia = j
            applied[eid] = {"inertia": np.diag(j).tolist(), "scale": [float(sx), float(sy)],
                            "scale_source": "least squares" if "inertia_scale_xx_least_squares" in p else
                            "the effect's fit (no instrument correction)"}
        elif eid == "gyro_scale":
            old = np.array(vehicle.gyro_scale or [1.0, 1.0, 1.0])
            out.gyro_scale = (old * np.array(p["scale"])).tolist()
            applied[eid] = {"gyro_scale": out.gyro_scale}
        elif eid == "com_offset":
            d = np.array([p["com_offset_x"], p["com_offset_y"], 0.0])
            out.rotors = [Rotor(tuple(float(v) for v in np.array(r.position) - d), r.yaw_sign) for r in out.rotors]
            out.com_offset = (np.array(vehicle.com_offset or [0.0, 0.0, 0.0]) + d).tolist()
            applied[eid] = {"com_offset": out.com_offset}
        elif eid == "aero_damping":
            d = np.array([p["damping_x"], p["damping_y"], p["damping_z"]])
            out.aero_damping = (np.array(vehicle.aero_damping or [0.0, 0.0, 0.0]) + d).tolist()
            applied[eid] = {"aero_damping": out.aero_damping}
        elif eid in ("rotor_inertia", "rotor_gyroscopic"):
            if p["rotor_inertia"] > 0 and "rotor_inertia" not in {k for a in applied.values() for k in a}:
                out.rotor_inertia = float(p["rotor_inertia"])
                applied[eid] = {"rotor_inertia": out.rotor_inertia}
        elif eid == "closed_loop_cancellation":
            # The filter's disturbance states take the torque below this edge (propid replay
            # --disturbance on passes it as the firmware's disturbance_bandwidth).
            out.loop_bandwidth_hz = float(p["loop_bandwidth_hz"])
            applied[eid] = {"loop_bandwidth_hz": out.loop_bandwidth_hz,
                            "at_least": bool(p.get("loop_bandwidth_at_least", False))}
        else:
            not_carried.append({"id": eid, "why": "no vehicle-file key for this effect"})
    notes = (" Corrected by propid gap: " + "; ".join(f"{k}: {v}" for k, v in applied.items())) if applied else ""
    out.notes = (vehicle.notes or "") + notes
    return out, {"applied": applied, "not_carried": not_carried}
