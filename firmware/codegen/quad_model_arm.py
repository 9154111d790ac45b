#!/usr/bin/env python3
"""The quad prediction's model stage as Cortex-M4 assembly (Thumb-2, VFPv4-SP).

Writes firmware/src/propid_quad_model.h: PROPID_ARM_MODEL_STAGE, the quad build
on a Cortex-M4 with the generated prediction kernel (PROPID_ARM_PREDICT_KERNEL);
every other build compiles the portable C, predict_stage_quad in
propid_predict.c, which stays the reference.

The model stage computes the predicted body rates (trapezoid input, Heun on the
gyroscopic term), the 18 entries of the rate rows of G = dt A (the thrust
entries through the torque basis, the drag entries through the yaw basis) and
the biases' sum of the stage's finiteness test. Compiled with -ffp-contract=fast
(the target build's flag) GCC fuses some of its products into additions and
subtractions (`vfma`, `vfms`) and leaves others alone: that choice decides the
bits. This module builds predict_stage_quad's statements three-address in the
C's order and applies GCC's rule for contracting them (expression_graph.py,
shared with the prediction kernel's generator).

The fused graph is then scheduled (any order of the same operations gives the
same bits) and its registers allocated here: the 18 entries end in s14-s31,
where the prediction kernel reads them; the filter's consecutive inputs (the
rotor speeds, the torque rows, the gyroscopic coefficients and the thrust basis,
the state) arrive by VLDM; the immediates 0.5 and 0.25 by VMOV, 0 and dt and
2/3 from core registers.

Checks: the generator runs its own assembly on the graph's nodes (each
instruction must compute the node its register is meant to hold);
tests/host_tools/test_codegen.py compares the graph with GCC's own contraction
of the portable C, output by output; the target test
qemu.block_moves_match_portable_c compares the final states of the builds with
and without the assembly to the bit.

    quad_model_arm.py [--out FILE] [--check]
"""

from __future__ import annotations

import pathlib
import re
import sys

from expression_graph import Graph
from generated_file import generator_main

OUT = pathlib.Path(__file__).resolve().parents[2] / "firmware" / "src" / "propid_quad_model.h"

ENTRIES = 6                  # G entries per rate row in the quad layout
G_BASE = 14                  # g_a,p in s(14 + 6 a + p), as the prediction kernel reads them
REGISTERS = 32


def g_register(a: int, p: int) -> int:
    return G_BASE + ENTRIES * a + p


def build():
    """predict_stage_quad (propid_predict.c) for the quad layout, mirrored.
    Returns the graph, its outputs g[a][p], the predictors, its outputs
    rate_next[a] and check."""
    graph = Graph(shared_leaves=True)
    dt = graph.leaf("dt")
    half = graph.leaf("K", 0.5)
    rate = [graph.leaf("S", a) for a in range(3)]
    half_dt = graph.mul(dt, half)
    speed_sq_dt = [graph.mul(half_dt, graph.add(graph.leaf("U", i), graph.leaf("V", i))) for i in range(4)]
    g = [[None] * ENTRIES for _ in range(3)]
    rotors, gyroscopic, predictor, entry0s, entry1s = [], [], [], [], []
    raw = []
    for a in range(3):
        other0 = 1 if a == 0 else 0
        other1 = 1 if a == 2 else 2
        quad_gyro = graph.leaf("Q", a)
        entry0 = graph.mul(dt, graph.mul(quad_gyro, rate[other1]))
        entry1 = graph.mul(dt, graph.mul(quad_gyro, rate[other0]))
        entry0s.append(entry0)
        entry1s.append(entry1)
        gyroscopic.append(graph.add(graph.mul(entry0, rate[other0]), graph.mul(entry1, rate[other1])))
        entry = [graph.mul(graph.leaf("J", (a, i)), speed_sq_dt[i]) for i in range(4)]
        raw.append(entry)
        if a < 2:
            w = [graph.leaf("W", k) for k in range(7)]
            along0 = graph.mul(entry[0], w[0])
            for i in range(1, 4):
                along0 = graph.add(along0, graph.mul(entry[i], w[i]))
            entry = [graph.sub(entry[i], graph.mul(along0, w[i])) for i in range(4)]
            along1 = graph.mul(entry[1], w[4])
            for i in range(2, 4):
                along1 = graph.add(along1, graph.mul(entry[i], w[3 + i]))
            entry = [entry[0]] + [graph.sub(entry[i], graph.mul(along1, w[3 + i])) for i in range(1, 4)]
            first = 3
        else:
            d = [graph.leaf("D", k) for k in range(4)]
            along = graph.mul(entry[0], d[0])
            for i in range(1, 4):
                along = graph.add(along, graph.mul(entry[i], d[i]))
            along = graph.mul(graph.leaf("K", 2.0 / 3.0), along)
            entry = [graph.sub(entry[i], graph.mul(along, d[i])) for i in range(4)]
            first = 7
        total = graph.leaf("K", 0.0, tag=a)
        for i in range(4):
            total = graph.add(total, graph.mul(entry[i], graph.leaf("S", first + i)))
            g[a][2 + i] = entry[i]
        rotors.append(total)
        predictor.append(graph.add(rate[a], graph.add(total, graph.mul(half, gyroscopic[a]))))
    quarter = graph.leaf("K", 0.25)
    # The second loop's rate, gyroscopic coefficient, dt and 0.5 set again.
    dt, half = graph.leaf("dt", None, 1), graph.leaf("K", 0.5, 1)
    rate_next = []
    for a in range(3):
        other0 = 1 if a == 0 else 0
        other1 = 1 if a == 2 else 2
        quad_gyro = graph.leaf("Q", a, 1)
        entry0 = graph.mul(dt, graph.mul(quad_gyro, predictor[other1]))
        entry1 = graph.mul(dt, graph.mul(quad_gyro, predictor[other0]))
        corrector = graph.add(graph.mul(entry0, predictor[other0]), graph.mul(entry1, predictor[other1]))
        # (dt (quad_gyro[a] rate[other1]) is the first loop's entry0: GCC computes it once)
        g[a][0] = graph.mul(half, graph.add(entry0, entry0s[a]))
        g[a][1] = graph.mul(half, graph.add(entry1, entry1s[a]))
        heun = graph.add(rotors[a], graph.mul(quarter, graph.add(gyroscopic[a], corrector)))
        rate_next.append(graph.add(graph.leaf("S", a, 1), heun))
    check = graph.add(graph.add(graph.leaf("S", 11), graph.leaf("S", 12)), graph.leaf("S", 13))
    outputs = [node for row in g for node in row] + rate_next + [check]
    graph.contract(outputs)
    graph.speed_sq_dt, graph.raw_entries, graph.rotors = speed_sq_dt, raw, rotors
    return graph, g, predictor, rate_next, check



# Where the assembly reads its inputs: one base register from the torque rows
# (float index 0) through the filter's derived data and its core (the offsets
# asserted in the C, below), one for the drag basis (a table in flash).
FILTER_INDEX = {"J": 0, "Q": 12, "W": 15, "S": 51, "V": 170, "U": 174}
FILTER_OFFSETS = (("derived.quad_gyro", 12), ("derived.thrust_basis", 15), ("core.state", 51),
                  ("core.rotor_speed_sq", 170), ("core.input_speed_sq", 174))


def location(node):
    """(base, float index) of a memory leaf."""
    if node.kind == "D":
        return "drag", node.key
    first = FILTER_INDEX[node.kind]
    if node.kind == "J":
        return "filter", first + 4 * node.key[0] + node.key[1]
    return "filter", first + node.key


def leaf_groups(graph):
    """The VLDM groups: runs of consecutive floats loaded together."""
    def run(kind, keys, tag=0):
        return [graph.leaves[(kind, k, tag)] for k in keys]
    return [
        run("V", range(4)) + run("U", range(4)),
        run("J", [(a, i) for a in range(3) for i in range(4)]),
        run("W", range(7)),
        run("D", range(4)),
        run("S", range(3, 11)),
        run("S", range(3)),
        run("Q", range(3)),
        run("Q", [0], 1), run("Q", [1, 2], 1),
        run("S", [0], 1), run("S", [1, 2], 1),
        run("S", range(11, 14)),
    ]


def schedule(graph, g, predictor, rate_next, check, groups):
    """The operations in order, each load group (one VLDM) right before the
    first operation that reads one of its members: the rotor-speed terms and
    the thrust entries of the roll and pitch rows, the yaw row's drag entries,
    the sums, gyroscopic terms and predictors, then axis by axis the Heun
    correction, the rate entries and the predicted rate; the biases' sum."""
    order = []
    done = set()
    group_of = {}
    for members in groups:
        for member in members:
            group_of[member] = members
    loaded = set()

    def put(node):
        if node in done:
            return
        done.add(node)
        if node.is_leaf():
            members = group_of.get(node)
            if members is None:
                order.append(("leaf", node))
            elif id(members) not in loaded:
                loaded.add(id(members))
                order.append(("group", members))
                done.update(members)
            return
        # (an accumulator's chain first, the leaves last: loaded when needed)
        args = node.args[2:] + node.args[:2] if node.kind in ("fma", "fms") else node.args
        for arg in [arg for arg in args if not arg.is_leaf()] + [arg for arg in args if arg.is_leaf()]:
            put(arg)
        order.append(("op", node))

    for node in graph.speed_sq_dt:
        put(node)
    for a in range(3):
        for node in graph.raw_entries[a]:
            put(node)
        for p in range(2, ENTRIES):
            put(g[a][p])
    for a in range(3):
        put(graph.rotors[a])
    for a in range(3):
        put(predictor[a])
    for a in range(3):
        put(g[a][0])
        put(g[a][1])
        put(rate_next[a])
    put(check)
    return order


class AllocationError(Exception):
    pass


def allocate(order, pinned, outputs, reserve=2):
    """Registers for every value of the straight-line `order` (a linear scan:
    each value's reads are known); returns the assembly lines, the registers
    of `outputs` and the instruction counts by kind."""
    reads = {}
    for index, (what, item) in enumerate(order):
        if what == "op":
            for arg in item.args:
                reads.setdefault(arg, []).append(index)
    end = len(order)
    for node in outputs:
        reads.setdefault(node, []).append(end)
    defined_at = {}
    for index, (what, item) in enumerate(order):
        for node in (item if what == "group" else [item]):
            defined_at[node] = index
    pin_start = {r: defined_at[node] for node, r in pinned.items()}

    def last_read(node):
        return max(reads.get(node, [defined_at[node]]))

    # Preferred register: a value last read as the accumulator of an fma/fms
    # that makes a pinned (or itself preferring) value takes that register.
    # So does the longest-lived operand of a multiplication or addition that
    # makes one: the value is computed into the register it leaves.
    prefer = {}
    for index in range(len(order) - 1, -1, -1):
        what, node = order[index]
        if what != "op":
            continue
        target = pinned.get(node, prefer.get(node))
        if target is None:
            continue
        operands = node.args[2:] if node.kind in ("fma", "fms") else node.args
        operands = [arg for arg in operands if not arg.is_leaf() and arg not in pinned
                    and arg not in prefer and last_read(arg) == index]
        if operands:
            prefer[min(operands, key=lambda arg: defined_at[arg])] = target

    # A value that an fma/fms continues in place lives as long as the chain.
    chain_end = {}
    for index in range(len(order) - 1, -1, -1):
        what, node = order[index]
        if what == "op" and node.kind in ("fma", "fms"):
            acc = node.args[2]
            if last_read(acc) == index and acc not in pinned:
                chain_end.setdefault(acc, chain_end.get(node, last_read(node)))

    def lifetime_end(node):
        return chain_end.get(node, last_read(node))

    # A pinned register is claimed from the first of its chain's values on.
    for node, r in prefer.items():
        pin_start[r] = min(pin_start[r], defined_at[node])

    reg, owner, lines, counts, bases, starts = {}, {}, [], {}, {}, {}

    def emit(kind, text):
        counts[kind] = counts.get(kind, 0) + 1
        lines.append(text)

    def allowed(r, node):
        if r in owner:
            return False
        start = pin_start.get(r)
        return start is None or pinned.get(node, prefer.get(node)) == r or lifetime_end(node) <= start

    def reservation(r):
        return pin_start.get(r, 10 ** 6)

    def choose(node):
        target = pinned.get(node, prefer.get(node))
        if target is not None and allowed(target, node):
            return target
        if node in pinned:
            raise AllocationError(f"s{pinned[node]} not free for its entry at {defined_at[node]}: {live()}")
        candidates = [r for r in range(REGISTERS) if allowed(r, node)]
        if not candidates:
            raise AllocationError(f"no free register at {defined_at[node]}: {live()}")
        return min(candidates, key=lambda r: (reservation(r), -r))

    def live():
        return ", ".join(f"s{r} {n.kind}{'' if n.key is None else n.key} (read until {last_read(n)})"
                         for r, n in sorted(owner.items()))

    def take(node, r):
        reg[node] = r
        owner[r] = node

    def release_dead(args, index):
        for arg in set(args):
            if arg in reg and last_read(arg) <= index:
                del owner[reg.pop(arg)]

    pending = {}              # member -> the rest of its group, loaded when one is needed

    def load_group(members, index):
        """One VLDM where the members find consecutive registers, else as few
        runs as fit, each from where the last ended; members beyond the
        registers kept free (`reserve`) wait until one of them is read."""
        for member in members:
            pending.pop(member, None)
        base, first = location(members[0])
        current = bases.setdefault(base, first)
        starts.setdefault(base, first)
        if current != first and len(members) <= 2:
            # (one or two loads at an offset: no base update)
            for k, member in enumerate(members):
                r = choose(member)
                emit("vldr", f"vldr s{r}, [%[{base}], #{4 * (first + k - current)}]")
                take(member, r)
            return
        if current != first:
            delta = 4 * (first - current)
            emit("add", f"{'add' if delta > 0 else 'sub'} %[{base}], %[{base}], #{abs(delta)}")
        position = 0
        first_read = {m: min(reads.get(m, [10 ** 6])) for m in members}
        need = max(members.index(m) for m in members if first_read[m] == min(first_read.values())) + 1
        while position < len(members):
            free = len([r for r in range(REGISTERS)
                        if r not in owner and pin_start.get(r, 10 ** 6) > index])
            best = None
            for r in range(REGISTERS):
                length = 0
                while (position + length < len(members) and r + length < REGISTERS
                       and allowed(r + length, members[position + length])):
                    length += 1
                length = min(length, max(need - position, free - reserve))
                if length <= 0:
                    continue
                score = (-length, sum(min(reservation(r + k), 10 ** 4) for k in range(length)))
                if best is None or score < best[0]:
                    best = (score, r, length)
            if best is None:
                if position < need:
                    raise AllocationError(f"no free register for a load at {index}")
                break
            _score, r, length = best
            registers = f"s{r}" if length == 1 else f"s{r}-s{r + length - 1}"
            emit("vldm", f"vldmia %[{base}]!, {{{registers}}}")
            for k in range(length):
                take(members[position + k], r + k)
            position += length
        bases[base] = first + position
        rest = members[position:]
        for member in rest:
            pending[member] = rest

    for index, (what, item) in enumerate(order):
        if what == "op":
            for arg in item.args:
                if arg not in reg and arg in pending:
                    load_group(pending[arg], index)
        if what == "group":
            load_group(item, index)
            continue
        node = item
        if what == "leaf":
            r = choose(node)
            if node.kind == "K" and node.key in (0.5, 0.25):
                emit("vmov", f"vmov.f32 s{r}, #{node.key}")
            elif node.kind == "K":
                emit("vmov", f"vmov s{r}, %[{'zero' if node.key == 0.0 else 'two_thirds'}]")
            elif node.kind == "dt":
                emit("vmov", f"vmov s{r}, %[dt]")
            else:
                raise AllocationError(f"leaf {node.kind}{node.key} outside the load groups")
            take(node, r)
            continue
        if node.kind in ("fma", "fms"):
            x, y, acc = node.args
            source = reg[acc]
            target = pinned.get(node, prefer.get(node))
            if last_read(acc) == index and (target in (None, source) or
                                            (node not in pinned and not allowed(target, node))):
                del owner[source]
                del reg[acc]
                r = source
            else:
                r = choose(node)
                emit("vmov", f"vmov.f32 s{r}, s{source}")
                release_dead([acc], index)
            mnemonic = "vfma" if node.kind == "fma" else "vfms"
            emit(mnemonic, f"{mnemonic}.f32 s{r}, s{reg[x]}, s{reg[y]}")
            release_dead([x, y], index)
            take(node, r)
        else:
            x, y = node.args
            text = f"s{reg[x]}, s{reg[y]}"
            release_dead([x, y], index)
            r = choose(node)
            mnemonic = {"mul": "vmul", "add": "vadd", "sub": "vsub"}[node.kind]
            emit(mnemonic, f"{mnemonic}.f32 s{r}, {text}")
            take(node, r)
    return lines, {node: reg[node] for node in outputs}, counts, starts


def structure(node, memo):
    """A node's value as a nested tuple (leaves by what they read)."""
    if node in memo:
        return memo[node]
    if node.is_leaf():
        value = ("K", node.key) if node.kind == "K" else ("dt",) if node.kind == "dt" else location(node)
    else:
        value = (node.kind,) + tuple(structure(arg, memo) for arg in node.args)
    memo[node] = value
    return value


def run_assembly(lines, starts):
    """The assembly run on symbolic registers: each register's value as a
    nested tuple, as structure() writes them."""
    regs = {}
    bases = dict(starts)
    for line in lines:
        m = re.fullmatch(r"vldr s(\d+), \[%\[(\w+)\], #(-?\d+)\]", line)
        if m:
            regs[int(m.group(1))] = (m.group(2), bases[m.group(2)] + int(m.group(3)) // 4)
            continue
        m = re.fullmatch(r"vldmia %\[(\w+)\]!, \{s(\d+)(?:-s(\d+))?\}", line)
        if m:
            first, last = int(m.group(2)), int(m.group(3) or m.group(2))
            for k in range(last - first + 1):
                regs[first + k] = (m.group(1), bases[m.group(1)] + k)
            bases[m.group(1)] += last - first + 1
            continue
        m = re.fullmatch(r"(add|sub) %\[(\w+)\], %\[\w+\], #(\d+)", line)
        if m:
            bases[m.group(2)] += (1 if m.group(1) == "add" else -1) * int(m.group(3)) // 4
            continue
        m = re.fullmatch(r"vmov\.f32 s(\d+), #([\d.]+)", line)
        if m:
            regs[int(m.group(1))] = ("K", float(m.group(2)))
            continue
        m = re.fullmatch(r"vmov s(\d+), %\[(\w+)\]", line)
        if m:
            regs[int(m.group(1))] = {"zero": ("K", 0.0), "two_thirds": ("K", 2.0 / 3.0), "dt": ("dt",)}[m.group(2)]
            continue
        m = re.fullmatch(r"vmov\.f32 s(\d+), s(\d+)", line)
        if m:
            regs[int(m.group(1))] = regs[int(m.group(2))]
            continue
        m = re.fullmatch(r"(vmul|vadd|vsub|vfma|vfms)\.f32 s(\d+), s(\d+), s(\d+)", line)
        if m:
            d, x, y = (int(m.group(k)) for k in (2, 3, 4))
            if m.group(1) in ("vfma", "vfms"):
                regs[d] = ("fma" if m.group(1) == "vfma" else "fms", regs[x], regs[y], regs[d])
            else:
                regs[d] = ({"vmul": "mul", "vadd": "add", "vsub": "sub"}[m.group(1)], regs[x], regs[y])
            continue
        raise ValueError(f"unknown line {line!r}")
    return regs


def stage():
    """The graph, the assembly lines, the output registers and the counts;
    checked by running the assembly on the graph's values."""
    graph, g, predictor, rate_next, check = build()
    pinned = {g[a][p]: g_register(a, p) for a in range(3) for p in range(ENTRIES)}
    outputs = [node for row in g for node in row] + rate_next + [check]
    order = schedule(graph, g, predictor, rate_next, check, leaf_groups(graph))
    lines, where, counts, starts = allocate(order, pinned, outputs)
    regs = run_assembly(lines, starts)
    memo = {}
    for node in outputs:
        if regs.get(where[node]) != structure(node, memo):
            raise AssertionError("the assembly does not compute its graph's output in s%d" % where[node])
    return graph, g, rate_next, check, lines, where, counts, starts


# offsetof(propid_filter_t, FIELD) - offsetof(propid_filter_t, derived.jac_torque), in floats.
FIELDS = {"J": "derived.jac_torque", "Q": "derived.quad_gyro", "W": "derived.thrust_basis",
          "S": "core.state", "V": "core.rotor_speed_sq", "U": "core.input_speed_sq"}


def c_function(g, rate_next, check, lines, where, counts, starts) -> str:
    """The C function around the assembly (GNU inline assembly, one statement)."""
    pins = []
    outputs = []
    stores = []
    for a in range(3):
        for p in range(ENTRIES):
            pins.append(f"    register float g{a}_{p} __asm__(\"s{where[g[a][p]]}\");")
            outputs.append(f"\"=&t\"(g{a}_{p})")
            stores.append(f"    jacobian_dt[{a}][{p}] = g{a}_{p};")
    for a in range(3):
        pins.append(f"    register float rate{a} __asm__(\"s{where[rate_next[a]]}\");")
        outputs.append(f"\"=&t\"(rate{a})")
        stores.append(f"    rate_next[{a}] = rate{a};")
    pins.append(f"    register float bias_sum __asm__(\"s{where[check]}\");")
    outputs.append("\"=&t\"(bias_sum)")
    stores.append("    *check = bias_sum;")
    used = set()
    for line in lines:
        for match in re.finditer(r"s(\d+)(?:-s(\d+))?", line):
            first, last = int(match.group(1)), int(match.group(2) or match.group(1))
            used.update(range(first, last + 1))
    clobbered = sorted(used - set(where.values()))
    clobbers = ", ".join(f"\"s{r}\"" for r in clobbered)
    body = "\n".join(f"        \"{line}\\n\\t\"" for line in lines)
    instructions = sum(counts.values())
    summary = ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
    asserts = "\n".join(
        f"    _Static_assert(offsetof(propid_filter_t, {field}) - TORQUE == 4u * {FILTER_INDEX[kind]}u,\n"
        f"                   \"{field}: the offsets below\");"
        for kind, field in FIELDS.items() if kind != "J")
    output_lines = []
    for start in range(0, len(outputs), 6):
        output_lines.append("          " + ", ".join(outputs[start:start + 6]))
    # (the filter base starts at its first load: the field it lies in, and on)
    base_kind = max((kind for kind in FILTER_INDEX if FILTER_INDEX[kind] <= starts["filter"]),
                    key=lambda kind: FILTER_INDEX[kind])
    extra = starts["filter"] - FILTER_INDEX[base_kind]
    filter_start = (f"(const float *)(const void *)((const char *)filter +\n"
                    f"                                                   offsetof(propid_filter_t, "
                    f"{FIELDS[base_kind]}){f' + 4u * {extra}u' if extra else ''})")
    return f"""/* Generated by firmware/codegen/quad_model_arm.py from predict_stage_quad
 * (propid_predict.c): do not edit (regenerate; tests/host_tools/test_codegen.py
 * checks it is current and that its fused multiply-adds are GCC's for that C).
 *
 * The quad prediction's model stage on the Cortex-M4 (PROPID_ARM_MODEL_STAGE):
 * predict_stage_quad's operations, the same fused multiply-adds (GCC's
 * contraction of that C, reproduced by the generator), so the same bits,
 * scheduled and register-allocated by the generator: the 18 Jacobian entries end
 * in s14-s31, where the prediction kernel (PROPID_ARM_PREDICT_KERNEL) reads them;
 * the rotor speeds, torque rows, gyroscopic coefficients, thrust basis and state
 * arrive by VLDM. {instructions} instructions ({summary}). */
#ifndef PROPID_QUAD_MODEL_H
#define PROPID_QUAD_MODEL_H

#include <stddef.h>

#include "propid_internal.h"
#include "propid_quad_predict.h"

#if PROPID_ARM_PREDICT_KERNEL && !defined(PROPID_NO_ARM_MODEL_STAGE)
#define PROPID_ARM_MODEL_STAGE 1
/* The predicted rates (before their bound test), the rate rows of G = dt A
 * (jacobian_dt) and the biases' sum of the finiteness test (check), from the
 * filter's state, rotor speeds and derived model; drag_basis: the yaw basis's
 * vector (propid_drag_basis). */
static inline __attribute__((always_inline)) void
propid_quad_model_stage_arm(const propid_filter_t *filter, const float *drag_basis, float dt,
                            float jacobian_dt[3][PROPID_JAC_ROW], float rate_next[3], float *check)
{{
#define TORQUE offsetof(propid_filter_t, derived.jac_torque)
{asserts}
#undef TORQUE
{chr(10).join(pins)}
    const float *filter_at = {filter_start};
    const float *drag_at = drag_basis;
    __asm__(
{body}
        : {(","+chr(10)+"          ").join(", ".join(outputs[s:s + 6]) for s in range(0, len(outputs), 6))},
          [filter] "+&r"(filter_at), [drag] "+&r"(drag_at)
        : [dt] "r"(propid_float_bits(dt)), [zero] "r"(0u), [two_thirds] "r"(propid_float_bits(2.0f / 3.0f))
        /* (it reads the filter and the basis: GCC's limit of 30 operands leaves
         * no room for them as memory operands) */
        : {clobbers}, "memory");
{chr(10).join(stores)}
}}
#else
#define PROPID_ARM_MODEL_STAGE 0
#endif

#endif /* PROPID_QUAD_MODEL_H */
"""


def generate() -> str:
    _graph, g, rate_next, check, lines, where, counts, starts = stage()
    return c_function(g, rate_next, check, lines, where, counts, starts)


def main() -> int:
    return generator_main("quad_model_arm", __doc__.splitlines()[0], OUT, generate)


if __name__ == "__main__":
    sys.exit(main())
