"""The generated firmware kernels are what their generator writes today
(firmware/codegen/): regenerating gives byte-identical files, and a stale or
hand-edited file is detected."""

from __future__ import annotations

import pathlib
import re
import shutil
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
GENERATOR = REPO / "firmware" / "codegen" / "quad_predict.py"
GENERATED = REPO / "firmware" / "src" / "propid_quad_predict.h"


def run_generator(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(GENERATOR), *args], capture_output=True, text=True)


def test_quad_predict_kernel_is_current():
    result = run_generator("--check")
    assert result.returncode == 0, result.stderr


def test_regenerating_gives_identical_file(tmp_path):
    out = tmp_path / "propid_quad_predict.h"
    assert run_generator("--out", str(out)).returncode == 0
    assert out.read_bytes() == GENERATED.read_bytes()


def test_edited_kernel_is_detected(tmp_path):
    edited = tmp_path / "propid_quad_predict.h"
    edited.write_text(GENERATED.read_text().replace("t0 * g1_2", "t1 * g1_2", 1))
    result = run_generator("--check", "--out", str(edited))
    assert result.returncode == 1
    assert "not current" in result.stderr


# The Cortex-M4 assembly kernel (PROPID_ARM_PREDICT_KERNEL) must execute the
# fused multiply-adds GCC makes of the portable C kernel: its graph is compared,
# element by element, with GCC's own after its contraction pass
# (-fdump-tree-widening_mul of propid_predict.c, the quad build without the
# assembly, the target flags). qemu.block_moves_match_portable_c compares the
# two builds' final states; this finds a product fused on the other side even
# where its rounding would vanish in that flight.
ARM_GCC = shutil.which("arm-none-eabi-gcc")
TARGET_FLAGS = ["-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard", "-std=c11", "-O2",
                "-DNDEBUG", "-fno-math-errno", "-ffp-contract=fast", "-DPROPID_QUAD_BUILD=1",
                "-DPROPID_NO_ARM_ASM"]


def gcc_contracted_stores(tmp_path):
    """Each covariance element the C kernel stores, as GCC's tree of MEM loads,
    products, sums and .FMA calls (leaves: SSA names and constants)."""
    subprocess.run([ARM_GCC, *TARGET_FLAGS, "-I", str(REPO / "firmware" / "include"),
                    "-I", str(REPO / "firmware" / "src"), "-c", str(REPO / "firmware" / "src" / "propid_predict.c"),
                    "-o", str(tmp_path / "p.o"), "-fdump-tree-widening_mul"], cwd=tmp_path, check=True)
    dump = next(tmp_path.glob("*.widening_mul")).read_text()
    body = dump[dump.index("propid_status_t propid_predict_step"):]
    body = body[:body.index("\n}\n")]
    # The kernel from its first load on (column 0's p0): the values before it
    # (the Jacobian entries, the noise's dt and psd) are its leaves.
    psd_lines = "\n".join(line for line in body.splitlines() if "kind_process_psd[" in line)
    body = psd_lines + "\n" + body[re.search(r"\n\s*p0_\d+ = MEM", body).start():]
    definitions, renamed, stores, psd = {}, {}, {}, {}
    for line in body.splitlines():
        line = line.strip()
        match = re.match(r'__asm__\(""\s*:\s*((?:"=t" \S+,? ?)+):((?: "\d" \S+,?)+)\);', line)
        if match:
            outputs = re.findall(r'"=t" ([^,\s]+)', match.group(1))
            inputs = re.findall(r'"\d" ([^,\s)]+)', match.group(2))
            renamed.update(zip(outputs, inputs))
            continue
        match = re.match(r"(\S+) = MEM\[\(float \*\)filter_\d+\(D\) \+ (\d+)B\];", line)
        if match:
            definitions[match.group(1)] = ("P", int(match.group(2)))
            continue
        match = re.match(r"MEM\[\(float \*\)filter_\d+\(D\) \+ (\d+)B\] = (\S+);", line)
        if match:
            stores[int(match.group(1))] = match.group(2)
            continue
        match = re.match(r"(\S+) = MEM\[.*\]\.kind_process_psd\[(\d)\];", line)
        if match:
            psd[match.group(1)] = int(match.group(2))
            continue
        match = re.match(r"(\S+) = \.FMA \((\S+), (\S+), (\S+)\);", line)
        if match:
            definitions[match.group(1)] = ("fma", *match.group(2, 3, 4))
            continue
        match = re.match(r"(\S+) = (\S+) ([*+]) (\S+);", line)
        if match:
            definitions[match.group(1)] = ("mul" if match.group(3) == "*" else "add", match.group(2), match.group(4))

    def tree(name):
        while name in renamed:
            name = renamed[name]
        definition = definitions.get(name)
        if definition is None:
            return ("psd", psd[name]) if name in psd else ("leaf", name)
        if definition[0] == "P":
            return definition
        return (definition[0],) + tuple(tree(arg) for arg in definition[1:])

    return {offset: tree(name) for offset, name in stores.items()}


@pytest.mark.skipif(ARM_GCC is None, reason="arm-none-eabi-gcc not installed")
def test_assembly_kernel_fuses_as_gcc_does(tmp_path):
    sys.path.insert(0, str(GENERATOR.parent))
    try:
        import quad_predict_arm
    finally:
        sys.path.pop(0)
    structure = [[1, 2, 3, 4, 5, 6], [0, 2, 3, 4, 5, 6], [0, 1, 7, 8, 9, 10]]
    graph, _g, stores, _columns, _order, _deferred = quad_predict_arm.build(structure)
    gcc = gcc_contracted_stores(tmp_path)
    psd_kind = {"psd_rate": 0, "psd_thrust": 1, "psd_drag": 2, "psd_bias": 3}
    cov_base = min(offset for t in gcc.values() for offset in _offsets(t))   # P_00 in the filter
    binding = {}

    def ours(node):
        if node.kind == "P":
            return ("P", cov_base + 4 * quad_predict_arm.cov_index(*node.key))
        if node.kind == "T" and node.key in psd_kind:
            return ("psd", psd_kind[node.key])
        if node.kind in ("G", "T"):
            return ("leaf", (node.kind, node.key))
        return (node.kind,) + tuple(ours(arg) for arg in node.args)

    def same(theirs, mine):
        if theirs[0] == "leaf" and mine[0] == "leaf":
            if mine[1] in binding:
                return binding[mine[1]] == theirs[1]
            if theirs[1] in binding.values():
                return False
            binding[mine[1]] = theirs[1]
            return True
        if theirs[0] != mine[0] or len(theirs) != len(mine):
            return False
        if theirs[0] in ("P", "psd"):
            return theirs[1] == mine[1]
        if theirs[0] == "fma" and not same(theirs[3], mine[3]):
            return False
        for order in ((1, 2), (2, 1)):           # the product's and the sum's operands commute
            saved = dict(binding)
            if same(theirs[1], mine[order[0]]) and same(theirs[2], mine[order[1]]):
                return True
            binding.clear()
            binding.update(saved)
        return False

    assert len(stores) == len(gcc) == 50
    for i, j, node, _after in stores:
        offset = cov_base + 4 * quad_predict_arm.cov_index(i, j)
        assert same(gcc[offset], ours(node)), f"P({i}, {j}) is not GCC's contraction of the C kernel"


def _offsets(tree):
    if tree[0] == "P":
        yield tree[1]
    elif tree[0] in ("mul", "add", "fma"):
        for arg in tree[1:]:
            yield from _offsets(arg)


# The model stage in assembly (PROPID_ARM_MODEL_STAGE, firmware/codegen/quad_model_arm.py):
# regenerated identically, and its graph GCC's contraction of predict_stage_quad.
MODEL_GENERATOR = REPO / "firmware" / "codegen" / "quad_model_arm.py"
MODEL_GENERATED = REPO / "firmware" / "src" / "propid_quad_model.h"


def test_quad_model_stage_is_current(tmp_path):
    result = subprocess.run([sys.executable, str(MODEL_GENERATOR), "--check"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    out = tmp_path / "propid_quad_model.h"
    assert subprocess.run([sys.executable, str(MODEL_GENERATOR), "--out", str(out)]).returncode == 0
    assert out.read_bytes() == MODEL_GENERATED.read_bytes()
    edited = tmp_path / "edited.h"
    edited.write_text(MODEL_GENERATED.read_text().replace("vfms.f32", "vfma.f32", 1))
    result = subprocess.run([sys.executable, str(MODEL_GENERATOR), "--check", "--out", str(edited)],
                            capture_output=True, text=True)
    assert result.returncode == 1 and "not current" in result.stderr


def gcc_contracted_model_stage(tmp_path):
    """predict_stage_quad's outputs in propid_predict_step (the quad build with the
    assembly prediction kernel but the C model stage, the target flags) as GCC's
    trees after its contraction pass: the 18 Jacobian entries (the kernel's
    register variables g<a>_<p>), the three predicted rates (the bound test's
    first three ABS_EXPRs) and the biases' sum (check_N). Leaves: ('filter',
    byte offset), ('drag', byte offset), ('const', value), ('dt',)."""
    subprocess.run([ARM_GCC, *TARGET_FLAGS[:-1], "-DPROPID_NO_ARM_MODEL_STAGE", "-I",
                    str(REPO / "firmware" / "include"), "-I", str(REPO / "firmware" / "src"), "-c",
                    str(REPO / "firmware" / "src" / "propid_predict.c"), "-o", str(tmp_path / "p.o"),
                    "-fdump-tree-widening_mul"], cwd=tmp_path, check=True)
    dump = next(tmp_path.glob("*.widening_mul")).read_text()
    body = dump[dump.index("propid_status_t propid_predict_step"):]
    body = body[:body.index("\n}\n")]
    definitions, outputs, rates = {}, {}, []
    for line in body.splitlines():
        line = line.strip()
        match = re.match(r"(\S+) = MEM\[\(const float \*\)filter_\d+\(D\) \+ (\d+)B\];", line)
        if match:
            definitions[match.group(1)] = ("filter", int(match.group(2)))
            continue
        match = re.match(r"(\S+) = MEM\[\(const float \*\)(_\d+)(?: \+ (\d+)B)?\];", line)
        if match:
            definitions[match.group(1)] = ("drag", int(match.group(3) or 0))
            continue
        match = re.match(r"(\S+) = \.FMA \((\S+), (\S+), (\S+)\);", line)
        if match:
            definitions[match.group(1)] = ("fma", *match.group(2, 3, 4))
            continue
        match = re.match(r"(\S+) = -(\S+);", line)
        if match:
            definitions[match.group(1)] = ("neg", match.group(2))
            continue
        match = re.match(r"(\S+) = (\S+) ([*+-]) (\S+);", line)
        if match:
            definitions[match.group(1)] = ({"*": "mul", "+": "add", "-": "sub"}[match.group(3)],
                                           match.group(2), match.group(4))
            continue
        match = re.match(r"(g[0-2]_[0-5]) = (\S+);", line)
        if match:
            outputs[match.group(1)] = match.group(2)
            continue
        match = re.match(r"\S+ = ABS_EXPR <(\S+)>;", line)
        if match and len(rates) < 3:
            rates.append(match.group(1))
    check = next(name for name in definitions if name.startswith("check_"))

    def tree(name):
        if re.fullmatch(r"-?\d+\.\d+e[+-]\d+|-?\d+\.\d+", name):
            return ("const", float(name))
        if re.fullmatch(r"dt_\d+\(D\)", name):
            return ("dt",)
        definition = definitions[name]
        if definition[0] in ("filter", "drag"):
            return definition
        if definition[0] == "fma":
            x, y, z = definition[1:]
            for negated, other in ((x, y), (y, x)):
                if definitions.get(negated, ("",))[0] == "neg":
                    return ("fms", tree(definitions[negated][1]), tree(other), tree(z))
            return ("fma", tree(x), tree(y), tree(z))
        return (definition[0],) + tuple(tree(arg) for arg in definition[1:])

    names = [outputs[f"g{a}_{p}"] for a in range(3) for p in range(6)] + rates + [check]
    return [tree(name) for name in names]


@pytest.mark.skipif(ARM_GCC is None, reason="arm-none-eabi-gcc not installed")
def test_assembly_model_stage_fuses_as_gcc_does(tmp_path):
    sys.path.insert(0, str(MODEL_GENERATOR.parent))
    try:
        import quad_model_arm
    finally:
        sys.path.pop(0)
    _graph, g, _predictor, rate_next, check = quad_model_arm.build()
    mine = [node for row in g for node in row] + rate_next + [check]
    theirs = gcc_contracted_model_stage(tmp_path)
    # The torque rows (float index 0 of the generator's filter locations) are the
    # first of the filter's fields the stage reads: GCC's lowest offset.
    torque = min(offset for tree in theirs for offset in _filter_offsets(tree))

    def ours(node):
        if node.kind == "K":
            return ("const", node.key)
        if node.kind == "dt":
            return ("dt",)
        if node.is_leaf():
            base, index = quad_model_arm.location(node)
            return (base, (torque if base == "filter" else 0) + 4 * index)
        return (node.kind,) + tuple(ours(arg) for arg in node.args)

    def same(gcc, own):
        if gcc[0] == "const" and own[0] == "const":
            return abs(gcc[1] - own[1]) <= 1e-7 * abs(own[1])
        if gcc[0] != own[0] or len(gcc) != len(own):
            return False
        if gcc[0] in ("dt", "filter", "drag"):
            return gcc == own
        if gcc[0] in ("fma", "fms") and not same(gcc[3], own[3]):
            return False
        if gcc[0] == "sub":
            return same(gcc[1], own[1]) and same(gcc[2], own[2])
        # (the product's and the sum's operands commute)
        return (same(gcc[1], own[1]) and same(gcc[2], own[2])) or (same(gcc[1], own[2]) and same(gcc[2], own[1]))

    assert len(theirs) == len(mine) == 22
    labels = [f"g{a}_{p}" for a in range(3) for p in range(6)] + ["rate_next[0]", "rate_next[1]",
                                                                    "rate_next[2]", "check"]
    for label, gcc, node in zip(labels, theirs, mine):
        assert same(gcc, ours(node)), f"{label} is not GCC's contraction of predict_stage_quad"


def _filter_offsets(tree):
    if tree[0] == "filter":
        yield tree[1]
    elif tree[0] in ("mul", "add", "sub", "fma", "fms"):
        for arg in tree[1:]:
            yield from _filter_offsets(arg)
