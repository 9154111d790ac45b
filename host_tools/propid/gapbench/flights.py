"""Fly one planned bench flight in propid_sitl: the blind log for the tool, the truth for the key.

The tool gets `flights/ID.csv` with the measured columns of flight-log v1 only (t,
gyro, rotor speeds, accelerometer, attitude, velocity, position, motor commands:
no truth, filter or reference columns) and `flights/ID.vehicle.json` with the
vehicle as described (nominal catalogue coefficients, no notes: the SITL's notes
name the effects). The truth goes to `answers/ID.json`, which only the scorer reads.

Strengths are chosen per flight from a target detectability (propid.gapbench
.magnitudes): probe flight at the effect's probe strength, index measured, strength
scaled linearly to the target and clipped to the plausible range, then the index
re-measured at that strength. A flight that diverges is re-drawn with another seed.

A diagnosis of K > 1 flights (`--flights-per-diagnosis`) flies the first flight as above,
then K - 1 more of the same vehicle (`--vehicle-seed` = the first flight's seed: the same
true coefficients and constant sensor biases) with the same effects at the same strengths,
their own noise seed and trajectory (plan.further_flight): `flights/ID.fN.csv`. Each gets
its own twins and probes, for its own D and the pooled D over the K flights
(detectability.pooled_detectability), both stored in the answer beside the first flight's.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

from propid.flightlog import read_vehicle
from propid.gapbench.detectability import detectability, pooled_detectability
from propid.gapbench.magnitudes import DETECTION_LIMIT, EFFECT_RANGES, clip_strength
from propid.gapbench.plan import FlightSpec, Trajectory, flights_per_diagnosis, further_flight
from propid.gapbench.sitl_log import read_sitl_log

EXIT_DIVERGED = 3
BLIND_NAMES = {"t", "gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z", "qw", "qx", "qy", "qz",
               "vx", "vy", "vz", "px", "py", "pz"}
BLIND_PER_ROTOR = re.compile(r"^(omega|cmd)_\d+$")
VEHICLE_KEYS = ("name", "mass", "inertia", "rotors", "kf_nominal", "km_nominal",
                "rotor_radius", "rotor_inertia")

# Ideal sensors for the detectability twins (same rates and latency as the flight).
CLEAN_SENSORS = ["--gyro-noise", "0", "--gyro-bias-max", "0", "--gyro-bias-walk", "0",
                 "--gyro-resolution", "0", "--gyro-range", "0", "--accel-noise", "0",
                 "--accel-bias-max", "0", "--esc-quantisation", "none", "--esc-dropout", "0"]
RETRIES = 4


class FlightFailed(RuntimeError):
    pass


def _blind_column(name: str) -> bool:
    return name in BLIND_NAMES or BLIND_PER_ROTOR.match(name) is not None


def write_blind_csv(full_csv: Path, out_csv: Path) -> list[str]:
    """Copy only the measured columns (text-level: the numbers stay byte-identical)."""
    with full_csv.open(encoding="utf-8") as src, out_csv.open("w", encoding="utf-8") as dst:
        header = src.readline().rstrip("\n").split(",")
        keep = [i for i, name in enumerate(header) if _blind_column(name)]
        dst.write(",".join(header[i] for i in keep) + "\n")
        for line in src:
            fields = line.rstrip("\n").split(",")
            dst.write(",".join(fields[i] for i in keep) + "\n")
    return [header[i] for i in keep]


def write_blind_vehicle(full_vehicle: Path, out_vehicle: Path) -> None:
    data = json.loads(full_vehicle.read_text(encoding="utf-8"))
    blind = {key: data.get(key) for key in VEHICLE_KEYS}
    blind["notes"] = ""
    out_vehicle.write_text(json.dumps(blind, indent=2) + "\n", encoding="utf-8")


def _effect_args(effects: dict[str, float]) -> list[str]:
    args: list[str] = []
    for name, strength in effects.items():
        args += ["--effect", f"{name}={strength:.6g}"]
    return args


class FlightMaker:
    def __init__(self, sitl: Path, out_dir: Path):
        self.sitl = Path(sitl)
        self.out_dir = Path(out_dir)

    def _base_args(self, spec: FlightSpec, seed: int, trajectory: Trajectory | None = None,
                   vehicle_seed: int | None = None) -> list[str]:
        vehicle_args = [] if vehicle_seed is None else ["--vehicle-seed", str(vehicle_seed)]
        return [str(self.sitl), "--quiet", "--mode", "incorrect", "--vehicle", spec.vehicle,
                "--seed", str(seed), *vehicle_args, "--duration", f"{spec.duration_s:g}",
                "--log-rate", str(spec.rates["log_rate"]), "--esc-rate", str(spec.rates["esc_rate"]),
                "--esc-latency", "0", "--esc-phase", "0",
                *(trajectory or spec.trajectory).sitl_args()]

    def _fly(self, args: list[str], log: Path) -> None:
        proc = subprocess.run(args + ["--log", str(log)], capture_output=True, text=True,
                              timeout=120, check=False)
        if proc.returncode == EXIT_DIVERGED:
            raise FlightFailed("diverged")
        if proc.returncode != 0:
            tail = " | ".join((proc.stderr or "").strip().splitlines()[-2:])
            raise RuntimeError(f"propid_sitl exit {proc.returncode}: {tail} ({' '.join(args)})")

    def make(self, spec: FlightSpec) -> dict:
        """Fly `spec` (and its further flights); write the blind files and the answer; return
        the answer."""
        last_error = ""
        for attempt in range(RETRIES):
            seed = spec.seed + 7919 * attempt
            with tempfile.TemporaryDirectory(prefix=f"gapbench_{spec.flight_id}_") as tmp:
                try:
                    answer, first = self._make(spec, seed, Path(tmp))
                    break
                except FlightFailed as exc:
                    last_error = str(exc)
        else:
            raise RuntimeError(f"flight {spec.flight_id}: {last_error} in {RETRIES} attempts")
        if flights_per_diagnosis(spec) > 1:
            self._make_further(spec, answer, first)
        self._write_answer(answer)
        return answer

    def _write_answer(self, answer: dict) -> None:
        answers = self.out_dir / "answers"
        answers.mkdir(parents=True, exist_ok=True)
        (answers / f"{answer['flight_id']}.json").write_text(json.dumps(answer, indent=1) + "\n",
                                                             encoding="utf-8")

    def _make_further(self, spec: FlightSpec, answer: dict, first: dict) -> None:
        """Flights 2..K of the first one's vehicle; their D and the pooled D into `answer`."""
        vehicle_seed = answer["seed_flown"]
        strengths = {e["id"]: e["strength"] for e in answer["effects"]}
        runs = [first]
        answer["further_flights"] = []
        for number in range(2, flights_per_diagnosis(spec) + 1):
            last_error = ""
            for attempt in range(RETRIES):
                seed, trajectory = further_flight(spec, number, attempt)
                with tempfile.TemporaryDirectory(prefix=f"gapbench_{spec.flight_id}_{number}_") as tmp:
                    try:
                        record, run = self._make_one_further(spec, number, seed, trajectory,
                                                             vehicle_seed, strengths, Path(tmp))
                        break
                    except FlightFailed as exc:
                        last_error = str(exc)
            else:
                raise RuntimeError(f"flight {spec.flight_id} number {number}: {last_error} in "
                                   f"{RETRIES} attempts")
            answer["further_flights"].append(record)
            runs.append(run)
        for entry in answer["effects"]:
            effect = entry["id"]
            entry["detectability_per_flight"] = [run["indices"][effect] for run in runs]
            entry["pooled_detectability"] = pooled_detectability(
                [(run["probes"][effect], run["twin"], run["noisy_twin"]) for run in runs],
                runs[0]["vehicle"])

    def _make_one_further(self, spec: FlightSpec, number: int, seed: int, trajectory: Trajectory,
                          vehicle_seed: int, strengths: dict[str, float], tmp: Path
                          ) -> tuple[dict, dict]:
        base = self._base_args(spec, seed, trajectory, vehicle_seed)
        noisy = base + spec.nuisances.sitl_args()
        run = self._twins_and_probes(base + CLEAN_SENSORS, noisy, strengths, tmp)
        flight_args = noisy + _effect_args(strengths)
        self._fly(flight_args, tmp / "flight.csv")
        name = f"{spec.flight_id}.f{number}.csv"
        write_blind_csv(tmp / "flight.csv", self.out_dir / "flights" / name)
        record = {"number": number, "csv": name, "seed_flown": seed, "vehicle_seed": vehicle_seed,
                  "trajectory": trajectory.__dict__.copy(), "detectability": run["indices"],
                  "sitl_command": " ".join([Path(flight_args[0]).name] + flight_args[1:])}
        return record, run

    def _twins_and_probes(self, clean: list[str], noisy: list[str], strengths: dict[str, float],
                          tmp: Path) -> dict:
        """Clean and noisy twins and one clean probe per effect at its strength, read back."""
        run: dict = {"probes": {}, "indices": {}}
        if not strengths:
            return run
        self._fly(clean, tmp / "clean_twin.csv")
        self._fly(noisy, tmp / "noisy_twin.csv")
        run["vehicle"] = read_vehicle(tmp / "clean_twin.vehicle.json")
        run["twin"] = read_sitl_log(tmp / "clean_twin.csv")
        run["noisy_twin"] = read_sitl_log(tmp / "noisy_twin.csv")
        for effect, strength in strengths.items():
            probe = tmp / f"probe_{effect}.csv"
            self._fly(clean + _effect_args({effect: strength}), probe)
            run["probes"][effect] = read_sitl_log(probe)
            run["indices"][effect] = detectability(run["probes"][effect], run["twin"],
                                                   run["noisy_twin"], run["vehicle"])["index"]
        return run

    def _make(self, spec: FlightSpec, seed: int, tmp: Path) -> tuple[dict, dict]:
        base = self._base_args(spec, seed)
        noisy = base + spec.nuisances.sitl_args()
        clean = base + CLEAN_SENSORS
        strengths: dict[str, float] = {}
        truth = []
        first: dict = {"probes": {}, "indices": {}}
        if spec.effects:
            self._fly(clean, tmp / "clean_twin.csv")
            self._fly(noisy, tmp / "noisy_twin.csv")
            vehicle = read_vehicle(tmp / "clean_twin.vehicle.json")
            twin = read_sitl_log(tmp / "clean_twin.csv")
            noisy_twin = read_sitl_log(tmp / "noisy_twin.csv")
            for effect, sign, target in zip(spec.effects, spec.signs, spec.target_detectability):
                probe = (sign if EFFECT_RANGES[effect].signed else 1) * EFFECT_RANGES[effect].probe
                self._fly(clean + _effect_args({effect: probe}), tmp / "probe.csv")
                probe_index = detectability(read_sitl_log(tmp / "probe.csv"), twin, noisy_twin,
                                            vehicle)["index"]
                wanted = probe * target / max(probe_index, 1e-9)
                strength, clipped = clip_strength(effect, wanted)
                self._fly(clean + _effect_args({effect: strength}), tmp / "probe.csv")
                probe_log = read_sitl_log(tmp / "probe.csv")
                measured = detectability(probe_log, twin, noisy_twin, vehicle)
                first["probes"][effect] = probe_log
                first["indices"][effect] = measured["index"]
                strengths[effect] = strength
                truth.append({
                    "id": effect, "strength": strength, "unit": EFFECT_RANGES[effect].unit,
                    "target_detectability": target, "probe_detectability": probe_index,
                    "detectability": measured["index"], "clipped": clipped,
                    "below_limit": measured["index"] < DETECTION_LIMIT,
                    "axes": measured["axes"],
                    "free_flight_share": measured["free_flight_share"],
                })
            first.update(vehicle=vehicle, twin=twin, noisy_twin=noisy_twin)
        flight_args = noisy + _effect_args(strengths)
        self._fly(flight_args, tmp / "flight.csv")
        flights = self.out_dir / "flights"
        flights.mkdir(parents=True, exist_ok=True)
        csv_path = flights / f"{spec.flight_id}.csv"
        columns = write_blind_csv(tmp / "flight.csv", csv_path)
        write_blind_vehicle(tmp / "flight.vehicle.json", flights / f"{spec.flight_id}.vehicle.json")
        answer = {
            "flight_id": spec.flight_id,
            "kind": spec.kind,
            "effects": truth,
            "truth": sorted(strengths) if strengths else ["none"],
            "spec": spec.to_dict(),
            "seed_flown": seed,
            "sitl_command": " ".join([Path(flight_args[0]).name] + flight_args[1:]),
            "columns": columns,
        }
        return answer, first


def clear(out_dir: Path) -> None:
    for name in ("flights", "answers", "tool", "baseline"):
        shutil.rmtree(Path(out_dir) / name, ignore_errors=True)

