#!/usr/bin/env python3
"""Write a vehicle's prepared setup (propid_setup_t) as a C constant.

    python3 firmware/codegen/setup_blob.py VEHICLE.json --out FILE.c
            [--name propid_vehicle_setup] [-D PROPID_QUAD_BUILD=1 ...] [--cc cc]

A flight controller that flies one vehicle does not need the configuration's
checks and derivation on board (propid_config.c, about 4.6 KB of flash in the
quad build): this script runs them on the host, once, at build time, and the
firmware starts the filter with propid_init_prepared(&filter, NAME), which
checks the setup's format, size and CRC-32 and the indices the step uses.

The derivation is the firmware's own: the script compiles firmware/src with the
host C compiler and the build's definitions (-D, default the quad build), fills
a propid_config_t from the vehicle file (propid_config_default, then the file's
fields), calls propid_setup_prepare and reads the setup's bytes. A config the
firmware refuses is refused here, with the field propid_config_check names. The
host rounds the derivation without fused multiply-adds, the Cortex-M4F build
with them: the two can differ in the last bit of a derived float.

The vehicle file (JSON) holds
    "rotors": {"count", "arm_m", "first_angle_rad", "first_yaw_sign",
               "thrust_coeff_nominal", "drag_coeff_nominal"}   (a symmetric frame:
                                       propid_config_set_symmetric)
    or "rotor": [{"position_m": [x, y, z], "yaw_sign", "thrust_coeff_nominal",
                  "drag_coeff_nominal"}, ...]
    "inertia_diag": [jxx, jyy, jzz] or "inertia": [[...], [...], [...]]
and any scalar field of propid_config_t by its name (e.g. "gate_sigma": 4.0).

The C file holds the bytes in a union with propid_setup_t and static asserts
on its size and member offsets, so a file made for another build or version
does not compile; propid_init_prepared refuses a damaged one at run time.
"""
from __future__ import annotations

import argparse
import json
import math
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile
import zlib

REPO = pathlib.Path(__file__).resolve().parents[2]
# Sources the generator's host program links (the propid_quad library's rule,
# firmware/CMakeLists.txt; the ABI and MAVLink files are no part of the filter).
NEVER = {"propid_abi.c", "propid_mavlink.c"}
NOT_IN_QUAD = {"propid_damage.c", "propid_model.c", "propid_input_compensation.c"}
SETUP_MEMBERS = ("format", "size", "config", "derived", "checksum")


class SetupError(Exception):
    """A one-line reason the setup could not be written."""


def config_fields(header: str) -> dict[str, str]:
    """Scalar fields of propid_config_t and their C types, from propid.h."""
    match = re.search(r"typedef struct \{(.*?)\} propid_config_t;", header, re.S)
    if not match:
        raise SetupError("propid.h: propid_config_t not found")
    body = re.sub(r"/\*.*?\*/", "", match.group(1), flags=re.S)
    return {name: ctype for ctype, name in
            re.findall(r"\b(float|uint8_t|uint16_t|uint32_t|int32_t)\s+(\w+)\s*;", body)}


INT_RANGE = {"uint8_t": (0, 255), "uint16_t": (0, 65535), "uint32_t": (0, 2**32 - 1),
             "int32_t": (-2**31, 2**31 - 1)}


def c_float(value, what: str) -> str:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SetupError(f"{what}: not a finite number: {value!r}")
    return f"{float(value)!r}f"


def c_scalar(name: str, ctype: str, value) -> str:
    if ctype == "float":
        return c_float(value, name)
    low, high = INT_RANGE[ctype]
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise SetupError(f"{name}: not an integer in [{low}, {high}]: {value!r}")
    return f"({ctype}){value}"


def driver_source(vehicle: dict, fields: dict[str, str]) -> str:
    """The host program: the vehicle's config, propid_setup_prepare, the bytes."""
    lines = ["propid_config_default(&config);"]
    if ("rotors" in vehicle) == ("rotor" in vehicle):
        raise SetupError('give the rotors either as "rotors" (symmetric) or as a "rotor" list')
    if "rotors" in vehicle:
        r = vehicle["rotors"]
        keys = ("count", "arm_m", "first_angle_rad", "first_yaw_sign", "thrust_coeff_nominal", "drag_coeff_nominal")
        if not isinstance(r, dict) or set(r) != set(keys):
            raise SetupError(f'"rotors" needs exactly {", ".join(keys)}')
        count = c_scalar("rotors.count", "uint8_t", r["count"])
        args = ", ".join(c_float(r[k], f"rotors.{k}") for k in keys[1:])
        lines.append(f'if (propid_config_set_symmetric(&config, {count}, {args}) != PROPID_OK) '
                     '{ puts("bad rotors"); return 2; }')
    else:
        rotors = vehicle["rotor"]
        if not isinstance(rotors, list) or not rotors or len(rotors) > 255:
            raise SetupError('"rotor" must be a non-empty list')
        lines.append(f"config.rotor_count = {len(rotors)}u;")
        lines.append(f'if (config.rotor_count > PROPID_MAX_ROTORS) {{ puts("bad rotor_count"); return 2; }}')
        for i, rotor in enumerate(rotors):
            keys = {"position_m", "yaw_sign", "thrust_coeff_nominal", "drag_coeff_nominal"}
            if not isinstance(rotor, dict) or set(rotor) != keys:
                raise SetupError(f"rotor[{i}] needs exactly {', '.join(sorted(keys))}")
            position = rotor["position_m"]
            if not isinstance(position, list) or len(position) != 3:
                raise SetupError(f"rotor[{i}].position_m: three numbers")
            for axis in range(3):
                lines.append(f"config.rotor[{i}].position_m[{axis}] = {c_float(position[axis], f'rotor[{i}].position_m')};")
            for key in sorted(keys - {"position_m"}):
                lines.append(f"config.rotor[{i}].{key} = {c_float(rotor[key], f'rotor[{i}].{key}')};")
    if ("inertia" in vehicle) == ("inertia_diag" in vehicle):
        raise SetupError('give the inertia either as "inertia_diag" or as a 3x3 "inertia"')
    if "inertia_diag" in vehicle:
        diag = vehicle["inertia_diag"]
        if not isinstance(diag, list) or len(diag) != 3:
            raise SetupError("inertia_diag: three numbers")
        lines.append("propid_config_set_inertia_diag(&config, "
                     + ", ".join(c_float(v, "inertia_diag") for v in diag) + ");")
    else:
        rows = vehicle["inertia"]
        if not isinstance(rows, list) or len(rows) != 3 or any(not isinstance(r, list) or len(r) != 3 for r in rows):
            raise SetupError("inertia: a 3x3 list")
        for a in range(3):
            for b in range(3):
                lines.append(f"config.inertia[{a}][{b}] = {c_float(rows[a][b], 'inertia')};")
    for name, value in vehicle.items():
        if name in ("rotors", "rotor", "inertia", "inertia_diag"):
            continue
        if name not in fields or name == "rotor_count":
            raise SetupError(f"unknown field {name!r} (a scalar field of propid_config_t)")
        lines.append(f"config.{name} = {c_scalar(name, fields[name], value)};")
    body = "\n    ".join(lines)
    offsets = " ".join(f"{m}=%zu" for m in SETUP_MEMBERS)
    offset_args = ", ".join(f"offsetof(propid_setup_t, {m})" for m in SETUP_MEMBERS)
    return f"""#include <stddef.h>
#include <stdio.h>
#include "propid/propid.h"
static propid_config_t config;
static propid_setup_t setup;
int main(void)
{{
    {body}
    const char *bad = NULL;
    if (propid_config_check(&config, &bad) != PROPID_OK) {{
        printf("bad %s\\n", bad != NULL ? bad : "config");
        return 2;
    }}
    if (propid_setup_prepare(&config, &setup) != PROPID_OK) {{
        puts("bad config");
        return 2;
    }}
    printf("sizeof=%zu {offsets}\\n", sizeof(setup), {offset_args});
    const unsigned char *bytes = (const unsigned char *)&setup;
    for (size_t k = 0; k < sizeof(setup); ++k) {{
        printf("%02x", bytes[k]);
    }}
    putchar('\\n');
    return 0;
}}
"""


def prepare(vehicle: dict, defines: list[str], cc: str) -> tuple[dict[str, int], bytes]:
    """Compile and run the host program; the layout it reports and the setup's bytes."""
    fields = config_fields((REPO / "firmware/include/propid/propid.h").read_text())
    source = driver_source(vehicle, fields)
    if shutil.which(cc) is None:
        raise SetupError(f"C compiler {cc!r} not found")
    quad = any(d.replace(" ", "") == "PROPID_QUAD_BUILD=1" for d in defines)
    left_out = NEVER | (NOT_IN_QUAD if quad else set())
    sources = [str(p) for p in sorted((REPO / "firmware/src").glob("propid_*.c")) if p.name not in left_out]
    with tempfile.TemporaryDirectory(prefix="propid_setup_") as tmp:
        driver = pathlib.Path(tmp) / "setup_driver.c"
        driver.write_text(source)
        program = pathlib.Path(tmp) / "setup_driver"
        # -ffp-contract=off: no fused multiply-adds, whatever the host's defaults.
        compile_cmd = [cc, "-std=c11", "-O1", "-ffp-contract=off", *(f"-D{d}" for d in defines),
                       "-I", str(REPO / "firmware/include"), str(driver), *sources, "-lm", "-o", str(program)]
        built = subprocess.run(compile_cmd, capture_output=True, text=True)
        if built.returncode != 0:
            first = next((line for line in built.stderr.splitlines() if "error" in line), built.stderr.strip())
            raise SetupError(f"host program did not compile: {first}")
        ran = subprocess.run([str(program)], capture_output=True, text=True)
    out = ran.stdout.split()
    if ran.returncode != 0:
        reason = " ".join(out[1:]) if out and out[0] == "bad" else ran.stderr.strip() or "host program failed"
        raise SetupError(f"configuration rejected: {reason}")
    layout = {key: int(value) for key, value in (item.split("=") for item in out[:-1])}
    blob = bytes.fromhex(out[-1])
    if len(blob) != layout["sizeof"]:
        raise SetupError("host program: setup size and bytes disagree")
    stored = int.from_bytes(blob[layout["checksum"]:layout["checksum"] + 4], "little")
    if stored != zlib.crc32(blob[:layout["checksum"]]):
        raise SetupError("host program: the setup's checksum is not the CRC-32 of its bytes")
    return layout, blob


def c_file(name: str, origin: str, defines: list[str], layout: dict[str, int], blob: bytes) -> str:
    rows = [", ".join(f"0x{b:02x}" for b in blob[k:k + 12]) for k in range(0, len(blob), 12)]
    data = ",\n        ".join(rows)
    asserts = "\n".join(f'_Static_assert(offsetof(propid_setup_t, {m}) == {layout[m]}u, "{name}: another layout");'
                        for m in SETUP_MEMBERS)
    build = " ".join(f"-D{d}" for d in defines) or "(no definitions)"
    return f"""/* Generated by firmware/codegen/setup_blob.py from {origin} for the build {build}:
 * the vehicle's prepared setup (propid_setup_t), for propid_init_prepared. Do not edit. */
#include <stddef.h>
#include <stdint.h>

#include "propid/propid.h"

_Static_assert(sizeof(propid_setup_t) == {layout["sizeof"]}u, "{name}: made for another build");
{asserts}

static const union {{
    uint8_t bytes[{len(blob)}];
    propid_setup_t setup;
}} setup_bytes = {{
    {{
        {data}
    }}
}};

const propid_setup_t *const {name} = &setup_bytes.setup;
"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("vehicle", type=pathlib.Path, help="vehicle file (JSON, fields above)")
    parser.add_argument("--out", type=pathlib.Path, required=True, help="C file to write")
    parser.add_argument("--name", default="propid_vehicle_setup",
                        help="name of the const propid_setup_t pointer (default %(default)s)")
    parser.add_argument("-D", dest="defines", action="append", default=None,
                        help="a build definition (repeat; default PROPID_QUAD_BUILD=1)")
    parser.add_argument("--cc", default="cc", help="host C compiler (default %(default)s)")
    args = parser.parse_args(argv)
    defines = args.defines if args.defines is not None else ["PROPID_QUAD_BUILD=1"]
    try:
        if not re.fullmatch(r"propid_\w+", args.name):
            raise SetupError(f"--name {args.name!r}: public symbols start with propid_")
        try:
            vehicle = json.loads(args.vehicle.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
            raise SetupError(f"cannot read a vehicle from it: {error}") from None
        if not isinstance(vehicle, dict):
            raise SetupError("a vehicle file holds one JSON object")
        layout, blob = prepare(vehicle, defines, args.cc)
        args.out.write_text(c_file(args.name, args.vehicle.name, defines, layout, blob))
    except SetupError as error:
        print(f"setup_blob: {args.vehicle}: {error}", file=sys.stderr)
        return 1
    print(f"setup_blob: {args.out}: {len(blob)} B setup for {args.vehicle.name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
