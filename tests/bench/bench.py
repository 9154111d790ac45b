#!/usr/bin/env python3
"""`make bench`: what the filter costs a flight controller and how fast the SITL runs.

    bench.py --repo DIR --build DIR [--out FILE] [--skip NAME,...]

A benchmark, not a test: it measures and reports, it does not pass or fail on
the figures (it fails only when a measurement cannot be made). Measurements:

  mcu        Cortex-M4 instructions per gyro step (tests/qemu/count_step.sh: QEMU
             instruction trace, target build flags): the quad build
             (PROPID_QUAD_BUILD=1, propid_config.h) for the quad and the dense
             baseline (tests/qemu/dense_ekf.c) beside it, checked to give the same
             estimates; the full build for 4, 6 and 8 rotors (*_full keys), and
             with each optional model term on (disturbance torque, rotor
             inertia, a held telemetry delay: mcu_instr_per_step_quad_<term>);
             the size-lean quad build (PROPID_SIZE_LEAN: its kernels as loops,
             *_lean keys).
  footprint  of the quad build (the issue's keys), of the size-lean quad build
             (*_lean) and of the full build (*_full):
             flash (.text + .rodata) of the filter alone, the library
             (build/target/firmware/libpropid_quad.a, libpropid.a) and linked
             into a minimal quad application with --gc-sections (step code and
             init-only code apart); RAM: sizeof(propid_filter_t) (full build for
             4, 6, 8 rotors); worst stack of every public call (-fcallgraph-info
             of the target build).
  sitl       propid_sitl's real-time factor (simulated s / CPU s) for the
             default 10 s Lissajous with default and with --paper sensors: the
             whole process, and the flight loop alone (its --summary-json
             flight_cpu_time_s); best of 31 runs of each, the two flights
             alternating, with the median, the slowest and the best of the
             first 7 (the method before the spread was printed).
  rotorpy    the same flight in RotorPy (PyPI, pinned, in a bench-only venv under
             the build directory), timed in the same run (CPU time of its
             sim.run()); the speed ratio against propid_sitl's flight loop (like
             for like) and against its whole process.
  table1     wall time of `make table1`.

Prints a table and writes every figure to --out (default BUILD/results/bench.json).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import re
import resource
import shutil
import statistics
import subprocess
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from bench_venv import ROTORPY_VERSION, ensure_bench_venv  # noqa: E402

CPU = ["-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard"]
TARGET_CFLAGS = CPU + ["-std=c11", "-O2", "-DNDEBUG", "-fno-math-errno", "-ffp-contract=fast",
                       "-ffunction-sections", "-fdata-sections"]
# Init-only sources compiled for size, as firmware/CMakeLists.txt does on the target.
INIT_ONLY_CFLAGS = {"propid_config.c": ["-Os"], "propid_setup.c": ["-Os"]}
# And in the size-lean quad build (firmware/CMakeLists.txt, PROPID_SIZE_LEAN_OS_SOURCES).
SIZE_LEAN_OS_SOURCES = ("propid_predict.c", "propid_filter.c", "propid_estimate.c", "propid_coeff_basis.c")
PER_SAMPLE_CALLS = ("propid_push_gyro", "propid_push_rotor_speeds", "propid_get_estimate")
# Cycles-per-instruction assumptions for the CPU-load estimate (docs/performance.md):
# Cortex-M4F at 168 MHz from flash with the ART/prefetch (FPU multiply-add 3 cycles,
# loads 2, taken branches 2-4, divide 14): 1.5; Cortex-M7 at 480 MHz from TCM/cache,
# dual issue: 1.0. Instruction counts are measured; these turn them into cycles.
CPU_MODELS = (("Cortex-M4F 168 MHz", 168e6, 1.5), ("Cortex-M7 480 MHz", 480e6, 1.0))
GYRO_RATES_HZ = (1000.0, 8000.0)
SECTIONS = ["mcu", "footprint", "sitl", "rotorpy", "table1"]


def say(text: str) -> None:
    print(f"bench: {text}", flush=True)


def run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, check=True, text=True, capture_output=True, **kw)


# ---------------------------------------------------------------------------
# Optional model terms counted by `make bench` (tests/qemu/count_step.c flags):
# the rotor inertia is a small multirotor's order of magnitude per rotor.
OPTION_FLAGS = (
    ("disturbance", "-DCOUNT_STEP_DISTURBANCE"),
    ("rotor_inertia", "-DCOUNT_STEP_ROTOR_INERTIA=6e-5f"),
    ("delay_4ms", "-DCOUNT_STEP_DELAY_US=4000"),
    ("input_noise", "-DCOUNT_STEP_INPUT_NOISE=2.0f"),
    ("input_compensation", "-DCOUNT_STEP_INPUT_NOISE=2.0f -DCOUNT_STEP_INPUT_COMPENSATION"),
    ("accel", "-DCOUNT_STEP_ACCEL"),
    ("accel_error", "-DCOUNT_STEP_ACCEL -DCOUNT_STEP_ACCEL_ERROR"),
)


# The size-lean quad build's flags (firmware/CMakeLists.txt, propid_quad_lean).
LEAN_FLAGS = "-DPROPID_QUAD_BUILD=1 -DPROPID_SIZE_LEAN=1"


def count_steps(repo: pathlib.Path, work: pathlib.Path, name: str, cflags: str) -> dict:
    out = work / f"count_step_{name}.json"
    env = {**os.environ, "COUNT_STEP_CFLAGS": cflags}
    run(["bash", str(repo / "tests/qemu/count_step.sh"), "--json", str(out), str(work / f"count_{name}")],
        env=env)
    return json.loads(out.read_text())


def bench_mcu(repo: pathlib.Path, work: pathlib.Path) -> dict:
    say("Cortex-M4 instruction counts under QEMU: quad build (quad, dense baseline)...")
    counts = count_steps(repo, work, "quad", "-DPROPID_QUAD_BUILD=1")
    say("Cortex-M4 instruction counts under QEMU: full build (quad, hexa, octo)...")
    full = count_steps(repo, work, "full", "-DCOUNT_STEP_NO_DENSE")
    say("Cortex-M4 instruction counts under QEMU: size-lean quad build (quad)...")
    lean = count_steps(repo, work, "quad_lean", f"{LEAN_FLAGS} -DCOUNT_STEP_NO_DENSE")
    variants = counts["variants"]
    full_variants = full["variants"]
    # Every optional model term the harness can switch on, full build (the
    # quad build compiles them out); same flight, same counting.
    options = {}
    for option, flag in OPTION_FLAGS:
        say(f"Cortex-M4 instruction counts under QEMU: full build with {option}...")
        options[option] = count_steps(repo, work, option, f"-DCOUNT_STEP_NO_DENSE {flag}")["variants"]
    result = {"variants": {k: {x: v[x] for x in ("median", "min", "max", "steps")}
                           for k, v in variants.items()},
              "variants_full": {k: {x: v[x] for x in ("median", "min", "max", "steps")}
                                for k, v in full_variants.items()},
              "variants_lean": {k: {x: v[x] for x in ("median", "min", "max", "steps")}
                                for k, v in lean["variants"].items()},
              "variants_options": {option: {k: {x: v[x] for x in ("median", "min", "max", "steps")}
                                            for k, v in counted.items()}
                                   for option, counted in options.items()},
              "dense_max_state_diff_in_std": counts.get("dense_max_state_diff_in_std"),
              "harness_output": counts["harness_output"] + full["harness_output"]}
    result["mcu_instr_per_step_quad"] = variants["quad_plus"]["median"]
    result["mcu_instr_per_step_quad_x"] = variants["quad_x"]["median"]
    result["mcu_instr_per_step_quad_full"] = full_variants["quad_plus"]["median"]
    result["mcu_instr_per_step_quad_lean"] = lean["variants"]["quad_plus"]["median"]
    result["mcu_instr_per_step_hexa"] = full_variants.get("hexa", {}).get("median")
    result["mcu_instr_per_step_octo"] = full_variants.get("octo", {}).get("median")
    result["dense_instr_per_step_quad"] = variants["dense_quad_plus"]["median"]
    for option, counted in options.items():
        result[f"mcu_instr_per_step_quad_{option}"] = counted["quad_plus"]["median"]
    result["dense_ratio_quad"] = result["dense_instr_per_step_quad"] / result["mcu_instr_per_step_quad"]
    # The stack the counted propid_push_gyro() calls really used (count_step.c
    # paints below the caller's stack pointer): beside the call graph's worst case.
    for build_name, output in (("", counts["harness_output"]), ("_full", full["harness_output"]),
                               ("_lean", lean["harness_output"])):
        used = [int(m.group(1)) for line in output
                for m in [re.search(r"^quad_plus: .* stack_used_push_gyro (\d+)", line)] if m]
        result[f"stack_bytes_push_gyro_measured{build_name}"] = used[0] if used else None
    load = {}
    for name, clock, cpi in CPU_MODELS:
        for rate in GYRO_RATES_HZ:
            load[f"{name}, {rate / 1000:.0f} kHz gyro"] = \
                100.0 * result["mcu_instr_per_step_quad"] * cpi * rate / clock
    result["cpu_percent_quad"] = load
    result["cpu_model_cpi"] = {name: cpi for name, _, cpi in CPU_MODELS}
    diff = result["dense_max_state_diff_in_std"]
    result["dense_same_estimates"] = diff is not None and diff < 0.01
    return result


# ---------------------------------------------------------------------------
def section_sizes(size_tool: str, path: pathlib.Path) -> dict[str, int]:
    """{object: .text + .rodata bytes} of an archive or object (size -A)."""
    sizes: dict[str, int] = {}
    current = path.name
    for line in run([size_tool, "-A", str(path)]).stdout.splitlines():
        m = re.match(r"^(\S+)\s+\(ex ", line)
        if m:
            current = m.group(1)
            continue
        parts = line.split()
        if len(parts) >= 2 and parts[1].isdigit() and (
                parts[0].startswith(".text") or parts[0].startswith(".rodata")):
            sizes[current] = sizes.get(current, 0) + int(parts[1])
    return sizes


def linked_filter_size(repo: pathlib.Path, work: pathlib.Path, build_flag: str,
                       per_sample: set[str], prepared: bool = False) -> dict:
    """Flash of the filter linked into a minimal application (--gc-sections),
    split into what the per-sample calls reach and the rest (init-only).
    prepared: the application starts the filter from the vehicle's prepared
    setup (propid_init_prepared), which the host generator writes; the setup's
    bytes count as the filter's."""
    # The quad build's library has neither the damage detector nor the model
    # helpers (firmware/CMakeLists.txt): they need the general build's data.
    left_out = {"propid_abi.c", "propid_mavlink.c"}
    if "-DPROPID_QUAD_BUILD=1" in build_flag.split():
        left_out |= {"propid_damage.c", "propid_model.c"}
    sources = [p for p in sorted((repo / "firmware/src").glob("propid_*.c")) if p.name not in left_out]
    tag = build_flag.replace("-D", "").replace("=", "_").replace(" ", "_").lower() + ("_prepared" if prepared else "")
    extra = []
    if prepared:
        setup_c = work / f"propid_vehicle_setup_{tag}.c"
        run([sys.executable, str(repo / "firmware/codegen/setup_blob.py"),
             str(repo / "tests/bench/footprint_vehicle.json"), "--out", str(setup_c),
             *(f"-D{d.removeprefix('-D')}" for d in build_flag.split())])
        extra = [setup_c]
    elf = work / f"footprint_app_{tag}.elf"
    map_file = work / f"footprint_app_{tag}.map"
    qemu = repo / "tests/qemu"
    objects_dir = work / f"footprint_objects_{tag}"
    objects_dir.mkdir(exist_ok=True)
    flags = [*TARGET_CFLAGS, *build_flag.split(), "-I", str(repo / "firmware/include"),
             "-I", str(qemu), *(["-DFOOTPRINT_PREPARED=1"] if prepared else [])]
    inputs = []
    lean = "-DPROPID_SIZE_LEAN=1" in build_flag.split()
    for source in [*sources, *extra, repo / "tests/bench/footprint_app.c", qemu / "startup.c",
                   qemu / "semihosting.c", qemu / "stack_watermark.c"]:
        obj = objects_dir / (source.stem + ".o")
        lean_os = ["-Os"] if lean and source.name in SIZE_LEAN_OS_SOURCES else []
        run(["arm-none-eabi-gcc", *flags, *INIT_ONLY_CFLAGS.get(source.name, []), *lean_os,
             "-c", str(source), "-o", str(obj)])
        inputs.append(str(obj))
    run(["arm-none-eabi-gcc", *CPU, *inputs, "-nostartfiles", "--specs=nano.specs",
         "--specs=nosys.specs", "-L", str(qemu), "-T", str(qemu / "mps2_an386.ld"),
         "-Wl,--gc-sections", f"-Wl,-Map={map_file}", "-lm", "-o", str(elf)])
    # Symbol sizes of the filter's own functions and constants in the linked ELF.
    filter_bytes = 0
    by_symbol: dict[str, int] = {}
    objects = {p.stem for p in [*sources, *extra]}
    text = map_file.read_text().split("Linker script and memory map", 1)[-1]
    # Map lines: " .text.name  0xADDR  0xSIZE  path/propid_x.o" (name may wrap).
    for m in re.finditer(r"^ (\.(?:text|rodata)\S*)\s*\n?\s+0x[0-9a-f]+\s+0x([0-9a-f]+)\s+(\S+)",
                         text, re.M):
        section, size, origin = m.group(1), int(m.group(2), 16), m.group(3)
        stem = pathlib.Path(origin.split("(")[-1].rstrip(")")).stem
        if any(stem.endswith(o) for o in objects):
            filter_bytes += size
            by_symbol[section] = by_symbol.get(section, 0) + size
    # .text.NAME holds function NAME (-ffunction-sections; static functions are
    # "file.c:NAME" in the call graph, clones "NAME.constprop.0" in both).
    reach = {name.rsplit(":", 1)[-1] for name in per_sample}
    # (GCC puts cold functions in .text.unlikely.NAME.)
    step_bytes = sum(size for name, size in by_symbol.items()
                     if name.startswith(".text.") and name[len(".text."):].removeprefix("unlikely.") in reach)
    return {"flash_bytes": filter_bytes, "flash_bytes_per_sample_path": step_bytes,
            "flash_bytes_init_and_rest": filter_bytes - step_bytes,
            "per_section": dict(sorted(by_symbol.items(), key=lambda kv: -kv[1]))}


def sizeof_filter(repo: pathlib.Path, work: pathlib.Path, build_flag: str) -> int:
    probe = work / "probe.c"
    probe.write_text('#include "propid/propid.h"\npropid_filter_t propid_footprint_probe;\n')
    obj = work / f"probe{build_flag.replace('-D', '').replace('=', '_').replace(' ', '_')}.o"
    run(["arm-none-eabi-gcc", *CPU, "-std=c11", "-O2", *build_flag.split(),
         "-I", str(repo / "firmware/include"), "-c", str(probe), "-o", str(obj)])
    for line in run(["arm-none-eabi-nm", "-S", "--radix=d", str(obj)]).stdout.splitlines():
        parts = line.split()
        if parts[-1] == "propid_footprint_probe":
            return int(parts[1])
    raise RuntimeError("sizeof probe failed")


def public_functions(repo: pathlib.Path) -> list[str]:
    header = (repo / "firmware/include/propid/propid.h").read_text()
    header = re.sub(r"static inline[^{]*\{[^}]*\}", "", header)
    return sorted(set(re.findall(r"\b(propid_[a-z_0-9]+)\s*\(", header)))


def footprint_of(repo: pathlib.Path, build: pathlib.Path, work: pathlib.Path, target: str,
                 build_flag: str) -> dict:
    """Flash, stack and linked size of one library of the target build."""
    library = build / f"target/firmware/lib{target}.a"
    if not library.exists():
        raise RuntimeError(f"{library} missing: run `make target` first")
    per_object = section_sizes("arm-none-eabi-size", library)
    # The filter alone: the propeller-damage detector is a separate, optional module.
    optional = {name: size for name, size in per_object.items() if "damage" in name}
    result: dict = {"flash_bytes": sum(per_object.values()) - sum(optional.values()),
                    "flash_bytes_optional_modules": optional, "flash_per_object": per_object}
    sys.path.insert(0, str(repo / "firmware/toolchain"))
    import stack_report  # noqa: E402  (the firmware's own call-graph reader)

    dirs = [str(d) for d in (build / f"target/firmware/CMakeFiles/{target}.dir",) if d.exists()]
    frames, _kinds, calls = stack_report.load(dirs)
    tails = stack_report.load_tail_calls(dirs)  # a tail call does not stack the caller's frame
    stacks = {}
    for function in public_functions(repo):
        if function in frames:
            depth, chain = stack_report.worst_chain(function, frames, calls, {}, [], tails)
            stacks[function] = {"bytes": depth, "chain": chain}
    result["stack"] = stacks
    # What the per-sample calls reach (the rest is configuration and init-only code).
    per_sample: set[str] = set()
    todo = list(PER_SAMPLE_CALLS)
    while todo:
        function = todo.pop()
        if function not in per_sample:
            per_sample.add(function)
            todo.extend(calls.get(function, ()))
    result["linked_quad"] = linked_filter_size(repo, work, build_flag, per_sample)
    if "-DPROPID_QUAD_BUILD=1" in build_flag.split():
        result["linked_quad_prepared"] = linked_filter_size(repo, work, build_flag, per_sample, prepared=True)
    result["stack_bytes_max"] = max(v["bytes"] for v in stacks.values())
    result["stack_bytes_push_gyro"] = stacks.get("propid_push_gyro", {}).get("bytes")
    return result


def bench_footprint(repo: pathlib.Path, build: pathlib.Path, work: pathlib.Path) -> dict:
    say("footprint of the target build (flash, RAM, stack), quad build and full build...")
    quad = footprint_of(repo, build, work, "propid_quad", "-DPROPID_QUAD_BUILD=1")
    full = footprint_of(repo, build, work, "propid", "-DPROPID_MAX_ROTORS=4")
    lean = footprint_of(repo, build, work, "propid_quad_lean", LEAN_FLAGS)
    result: dict = {"quad_build": quad, "full_build": full, "lean_build": lean}
    # The size-lean quad build (PROPID_SIZE_LEAN) beside the quad build.
    result["flash_bytes_lean"] = lean["flash_bytes"]
    result["flash_bytes_linked_quad_lean"] = lean["linked_quad"]["flash_bytes"]
    result["flash_bytes_linked_quad_lean_prepared"] = lean["linked_quad_prepared"]["flash_bytes"]
    result["ram_bytes_quad_lean"] = sizeof_filter(repo, work, LEAN_FLAGS)
    result["stack_bytes_max_lean"] = lean["stack_bytes_max"]
    result["stack_bytes_push_gyro_lean"] = lean["stack_bytes_push_gyro"]
    result["flash_bytes"] = quad["flash_bytes"]
    result["flash_bytes_linked_quad"] = quad["linked_quad"]["flash_bytes"]
    result["flash_bytes_linked_quad_prepared"] = quad["linked_quad_prepared"]["flash_bytes"]
    result["flash_bytes_full"] = full["flash_bytes"]
    result["flash_bytes_linked_quad_full"] = full["linked_quad"]["flash_bytes"]
    result["ram_bytes_quad"] = sizeof_filter(repo, work, "-DPROPID_QUAD_BUILD=1")
    for rotors, key in ((4, "ram_bytes_quad_full"), (6, "ram_bytes_hexa"), (8, "ram_bytes_octo")):
        result[key] = sizeof_filter(repo, work, f"-DPROPID_MAX_ROTORS={rotors}")
    result["stack_bytes_max"] = quad["stack_bytes_max"]
    result["stack_bytes_push_gyro"] = quad["stack_bytes_push_gyro"]
    result["stack_bytes_max_full"] = full["stack_bytes_max"]
    result["stack_bytes_push_gyro_full"] = full["stack_bytes_push_gyro"]
    return result


# ---------------------------------------------------------------------------
# Runs of each SITL flight. CPU time of a fixed flight only gains from noise (other
# processes, cache and frequency), so the fastest run is the estimate and more runs find a
# quieter moment; the two flights alternate so both see the same machine. Until the figures'
# spread was printed the bench took the best of 7 consecutive runs of each flight (its key
# ..._best_of_7 keeps that figure: the first 7 runs).
SITL_RUNS = 31
SITL_EARLIER_RUNS = 7


def cpu_seconds(cmd: list[str], summary: pathlib.Path) -> tuple[float, float]:
    """One run: (CPU s of the whole process, CPU s of the flight loop alone as
    propid_sitl reports it in its --summary-json)."""
    # Each run writes a new summary file, as every flight of a campaign does:
    # truncating the previous one makes ext4 write it back at close (~0.1 ms
    # of system time that is the file system's, not the simulator's).
    summary.unlink(missing_ok=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([*cmd, "--summary-json", str(summary)], check=True, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    process = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return process, float(json.loads(summary.read_text())["flight_cpu_time_s"])


def bench_sitl(build: pathlib.Path, work: pathlib.Path) -> dict:
    say(f"SITL real-time factor (CPU time, best of {SITL_RUNS} alternating runs of each flight)...")
    sitl = build / "host/sitl/propid_sitl"
    if not sitl.exists():
        raise RuntimeError(f"{sitl} missing: run `make host` first")
    result = {"flight": "propid_sitl --quiet (crazyflie-plus, lissajous, filter mode, 10 s)",
              "runs": SITL_RUNS}
    flights = (("sitl_realtime_factor", []), ("sitl_realtime_factor_paper", ["--paper"]))
    times = {key: ([], []) for key, _ in flights}
    for _ in range(SITL_RUNS):
        for key, extra in flights:
            process, flight = cpu_seconds([str(sitl), "--quiet", "--duration", "10", *extra],
                                          work / "sitl_summary.json")
            times[key][0].append(process)
            times[key][1].append(flight)
    for key, _ in flights:
        process, flight = times[key]
        # The whole process (exec, dynamic linking, set-up, the flight, exit) ...
        result[key] = 10.0 / min(process)
        result[key.replace("realtime_factor", "cpu_s")] = min(process)
        result[key + "_median"] = 10.0 / statistics.median(process)
        result[key + "_slowest"] = 10.0 / max(process)
        result[key + "_best_of_7"] = 10.0 / min(process[:SITL_EARLIER_RUNS])
        # ... and the flight loop alone, which is what the RotorPy figure times.
        result[key + "_flight"] = 10.0 / min(flight)
        result[key.replace("realtime_factor", "flight_cpu_s")] = min(flight)
        result[key + "_flight_median"] = 10.0 / statistics.median(flight)
        result[key + "_flight_best_of_7"] = 10.0 / min(flight[:SITL_EARLIER_RUNS])
    return result


def bench_rotorpy(repo: pathlib.Path, build: pathlib.Path, sitl: dict | None) -> dict:
    # RotorPy's speed depends on numpy/scipy: the bench venv installs every package
    # pinned with its hash (host_tools/setup/bench-requirements.txt, tests/bench/bench_venv.py).
    pins = repo / "host_tools/setup/bench-requirements.txt"
    result: dict = {"rotorpy_pinned": ROTORPY_VERSION, "rotorpy_requirements": str(pins.relative_to(repo))}
    try:
        python = ensure_bench_venv(repo, build, say)
    except (subprocess.CalledProcessError, OSError) as error:
        detail = getattr(error, "stderr", "") or str(error)
        result["rotorpy_error"] = f"rotorpy {ROTORPY_VERSION} could not be installed: " + \
            detail.strip().splitlines()[-1] if detail.strip() else "unknown error"
        say(result["rotorpy_error"])
        return result
    say("RotorPy: the same 10 s flight (CPU time)...")
    out = run([str(python), str(repo / "tests/bench/rotorpy_flight.py"), "--duration", "10"],
              cwd=build).stdout
    rotorpy = json.loads(out.strip().splitlines()[-1])
    result.update({f"rotorpy_{k}" if not k.startswith("rotorpy") else k: v
                   for k, v in rotorpy.items()})
    if sitl and "sitl_realtime_factor" in sitl:
        # Like for like: RotorPy's figure is the CPU time of sim.run() (no imports,
        # no set-up), so it is set against propid_sitl's flight loop alone.
        result["rotorpy_speed_ratio"] = \
            sitl["sitl_realtime_factor_flight"] / rotorpy["realtime_factor"]
        result["rotorpy_speed_ratio_whole_process"] = \
            sitl["sitl_realtime_factor"] / rotorpy["realtime_factor"]
    return result


def bench_table1(repo: pathlib.Path, work: pathlib.Path) -> dict:
    say("wall time of `make table1` (the campaign, a few minutes)...")
    start = time.monotonic()
    run(["make", "-C", str(repo), "--no-print-directory", "table1",
         f"TABLE1_OUT={work / 'table1'}"])
    return {"table1_wall_s": time.monotonic() - start}


# ---------------------------------------------------------------------------
def fmt(value, spec: str = ",.0f") -> str:
    return "n/a" if value is None else format(value, spec)


def print_table(r: dict) -> None:
    rows = []
    mcu, fp, sitl, rp, t1 = (r.get(k, {}) for k in SECTIONS)
    if mcu:
        names = {"quad_plus": "quad (plus)", "quad_x": "quad (X)",
                 "dense_quad_plus": "dense baseline, quad"}
        for build_name, key in (("quad build", "variants"), ("size-lean quad build", "variants_lean"),
                                ("full build", "variants_full")):
            for label, counts in mcu.get(key, {}).items():  # every variant the harness flew
                rows.append((f"Cortex-M4 instructions per step, {build_name}, {names.get(label, label)}",
                             f"{fmt(counts['median'])} ({fmt(counts['min'])}-{fmt(counts['max'])})"))
        for option, counted in mcu.get("variants_options", {}).items():
            rows.append((f"Cortex-M4 instructions per step, full build + {option}, quad (plus) / hexa / octo",
                         " / ".join(fmt(counted[v]["median"]) for v in ("quad_plus", "hexa", "octo")
                                    if v in counted)))
        for key, percent in mcu["cpu_percent_quad"].items():
            rows.append((f"CPU load, quad, {key} (CPI {mcu['cpu_model_cpi'][key.split(',')[0]]})",
                         f"{percent:.2f} %"))
        rows.append(("stack used by propid_push_gyro, quad flight, measured under QEMU, "
                     "quad / size-lean quad / full build (B)",
                     f"{fmt(mcu.get('stack_bytes_push_gyro_measured'))} / "
                     f"{fmt(mcu.get('stack_bytes_push_gyro_measured_lean'))} / "
                     f"{fmt(mcu.get('stack_bytes_push_gyro_measured_full'))}"))
        rows.append(("dense / propid (quad)", f"{mcu['dense_ratio_quad']:.1f}x; same estimates: "
                     f"{'yes' if mcu['dense_same_estimates'] else 'NO'} (max diff "
                     f"{mcu['dense_max_state_diff_in_std']:.1e} std)"))
    if fp:
        for build_name, key in (("quad build", "quad_build"), ("size-lean quad build", "lean_build"),
                                ("full build", "full_build")):
            b = fp[key]
            rows.append((f"filter flash, {build_name}, library .text+.rodata (B)", fmt(b["flash_bytes"]) +
                         "".join(f" (+ {name}: {fmt(size)}, optional)"
                                 for name, size in b.get("flash_bytes_optional_modules", {}).items())))
            lq = b["linked_quad"]
            rows.append((f"filter flash, {build_name}, linked quad app, --gc-sections (B)",
                         f"{fmt(lq['flash_bytes'])} (per-sample path {fmt(lq['flash_bytes_per_sample_path'])}, "
                         f"init and rest {fmt(lq['flash_bytes_init_and_rest'])})"))
            if "linked_quad_prepared" in b:
                lp = b["linked_quad_prepared"]
                rows.append((f"filter flash, {build_name}, linked quad app started from a prepared setup (B)",
                             f"{fmt(lp['flash_bytes'])} (per-sample path {fmt(lp['flash_bytes_per_sample_path'])}, "
                             f"init, setup and rest {fmt(lp['flash_bytes_init_and_rest'])})"))
        rows.append(("RAM sizeof(propid_filter_t), quad build / size-lean quad build (B)",
                     f"{fmt(fp['ram_bytes_quad'])} / {fmt(fp['ram_bytes_quad_lean'])}"))
        rows.append(("RAM sizeof(propid_filter_t), full build quad / hexa / octo (B)",
                     f"{fmt(fp['ram_bytes_quad_full'])} / {fmt(fp['ram_bytes_hexa'])} / {fmt(fp['ram_bytes_octo'])}"))
        for build_name, key in (("quad build", "quad_build"), ("size-lean quad build", "lean_build"),
                                ("full build", "full_build")):
            for name, st in sorted(fp[key]["stack"].items(), key=lambda kv: -kv[1]["bytes"]):
                rows.append((f"worst stack, {build_name}, {name} (B)", fmt(st["bytes"])))
    if sitl:
        for label, key in (("SITL 10 s Lissajous, real-time factor (CPU, whole process)",
                            "sitl_realtime_factor"),
                           ("SITL same with --paper sensors", "sitl_realtime_factor_paper")):
            rows.append((f"{label}, best of {sitl['runs']}",
                         f"{fmt(sitl[key])}x (flight loop alone {fmt(sitl[key + '_flight'])}x)"))
            rows.append(("  its runs: median; slowest; best of the first 7 (the earlier method)",
                         f"{fmt(sitl[key + '_median'])}x ({fmt(sitl[key + '_flight_median'])}x); "
                         f"{fmt(sitl[key + '_slowest'])}x; {fmt(sitl[key + '_best_of_7'])}x "
                         f"({fmt(sitl[key + '_flight_best_of_7'])}x)"))
    if rp:
        if "rotorpy_error" in rp:
            rows.append(("RotorPy", rp["rotorpy_error"]))
        else:
            rows.append((f"RotorPy {rp.get('rotorpy_version')} same flight, real-time factor (CPU)",
                         f"{rp['rotorpy_realtime_factor']:.2f}x at {fmt(rp['rotorpy_sim_rate_hz'])} Hz"))
            if "rotorpy_speed_ratio" in rp:
                rows.append(("propid_sitl / RotorPy speed (flight loops, CPU)",
                             f"{fmt(rp['rotorpy_speed_ratio'])}x (whole propid_sitl process: "
                             f"{fmt(rp['rotorpy_speed_ratio_whole_process'])}x)"))
    if t1:
        rows.append(("make table1 wall time", f"{t1['table1_wall_s']:.0f} s"))
    width = max(len(a) for a, _ in rows)
    print()
    print(f"{'figure':<{width}}  value")
    print(f"{'-' * width}  {'-' * 30}")
    for a, b in rows:
        print(f"{a:<{width}}  {b}")
    print()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", required=True, type=pathlib.Path)
    parser.add_argument("--build", required=True, type=pathlib.Path)
    parser.add_argument("--out", type=pathlib.Path, help="JSON (default BUILD/results/bench.json)")
    parser.add_argument("--skip", default="", help=f"comma list of {','.join(SECTIONS)}")
    args = parser.parse_args()
    skip = {s for s in args.skip.split(",") if s}
    if skip - set(SECTIONS):
        parser.error(f"--skip: unknown {sorted(skip - set(SECTIONS))}")
    repo, build = args.repo.resolve(), args.build.resolve()
    work = build / "bench"
    work.mkdir(parents=True, exist_ok=True)
    out = args.out or build / "results/bench.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    results: dict = {}
    try:
        if "mcu" not in skip:
            results["mcu"] = bench_mcu(repo, work)
        if "footprint" not in skip:
            results["footprint"] = bench_footprint(repo, build, work)
        if "sitl" not in skip:
            results["sitl"] = bench_sitl(build, work)
        if "rotorpy" not in skip:
            results["rotorpy"] = bench_rotorpy(repo, build, results.get("sitl"))
        if "table1" not in skip:
            results["table1"] = bench_table1(repo, work)
    except (subprocess.CalledProcessError, RuntimeError) as error:
        detail = getattr(error, "stderr", None) or ""
        print(f"bench: failed: {error}\n{detail[-2000:]}", file=sys.stderr)
        return 1
    flat = {}
    for section in results.values():
        for key in ("mcu_instr_per_step_quad", "mcu_instr_per_step_quad_full", "mcu_instr_per_step_hexa",
                    "mcu_instr_per_step_octo", "dense_instr_per_step_quad", "dense_ratio_quad",
                    "flash_bytes", "flash_bytes_linked_quad", "flash_bytes_full",
                    "flash_bytes_linked_quad_full", "ram_bytes_quad", "ram_bytes_quad_full",
                    "ram_bytes_hexa", "ram_bytes_octo", "stack_bytes_max", "stack_bytes_push_gyro",
                    "stack_bytes_push_gyro_measured", "stack_bytes_push_gyro_measured_full",
                    "stack_bytes_max_full", "stack_bytes_push_gyro_full",
                    "mcu_instr_per_step_quad_lean", "flash_bytes_lean", "flash_bytes_linked_quad_lean",
                    "flash_bytes_linked_quad_prepared", "flash_bytes_linked_quad_lean_prepared",
                    "ram_bytes_quad_lean", "stack_bytes_max_lean", "stack_bytes_push_gyro_lean",
                    "stack_bytes_push_gyro_measured_lean",
                    "sitl_realtime_factor", "sitl_realtime_factor_paper",
                    "sitl_realtime_factor_flight", "sitl_realtime_factor_paper_flight",
                    "sitl_realtime_factor_median", "sitl_realtime_factor_paper_median",
                    "sitl_realtime_factor_best_of_7", "sitl_realtime_factor_paper_best_of_7",
                    "rotorpy_speed_ratio", "rotorpy_speed_ratio_whole_process",
                    "table1_wall_s"):
            if key in section:
                flat[key] = section[key]
    document = {**flat, "details": results,
                "machine": {"cpus": os.cpu_count(), "python": sys.version.split()[0]}}
    out.write_text(json.dumps(document, indent=1) + "\n")
    print_table(results)
    say(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
