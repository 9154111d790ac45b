#!/usr/bin/env python3
"""Worst-case stack depth of the firmware's call chains, from GCC's
-fcallgraph-info=su files (.ci, one per object; the toolchain file turns them on).

Each .ci file lists the functions of one object with their own frame size and
the calls they make. Merging all files of the firmware libraries gives the call
graph; the deepest chain from each public entry point is its worst-case stack
(frames of library functions outside our objects, e.g. memset, are unknown and
counted as 0: the report names them). A cycle in the graph is recursion, which
the firmware rules forbid.

A tail call (the caller's frame is released before it branches to the callee,
`b` instead of `bl`) does not stack the two frames: the callee's chain then
counts without the caller's frame. Tail calls are read from the objects' code
(objdump -dr next to each .ci file: a branch without link relocated to a
function); without objdump every call counts as a call (an over-estimate).

    stack_report.py [--budget FUNCTION=BYTES]... DIR...

Prints the worst chains from the entry points (functions nothing else in these
objects calls, i.e. the API); exits 1 on recursion,
on a dynamically sized frame, or when a budget is exceeded.
"""

from __future__ import annotations

import argparse
import pathlib
import re
import shutil
import subprocess
import sys

NODE = re.compile(r'node: \{ title: "([^"]+)" label: "([^"]*)"')
EDGE = re.compile(r'edge: \{ sourcename: "([^"]+)" targetname: "([^"]+)"')
FRAME = re.compile(r"\\n(\d+) bytes \((\w+)")
NODE_TITLE = re.compile(r'node: \{ title: "([^"]+)"')
TAIL_MARK = "(tail) "  # printed before a callee reached by a tail call


def load(directories: list[str]) -> tuple[dict[str, int], dict[str, str], dict[str, set[str]]]:
    frames: dict[str, int] = {}
    kinds: dict[str, str] = {}
    calls: dict[str, set[str]] = {}
    files = sorted(p for d in directories for p in pathlib.Path(d).rglob("*.ci"))
    if not files:
        raise SystemExit(f"stack_report: no .ci files under {' '.join(directories)}")
    for path in files:
        for line in path.read_text().splitlines():
            node = NODE.search(line)
            if node:
                frame = FRAME.search(node.group(2))
                if frame:  # defined in this object (otherwise only declared)
                    frames[node.group(1)] = int(frame.group(1))
                    kinds[node.group(1)] = frame.group(2)
                continue
            edge = EDGE.search(line)
            if edge:
                calls.setdefault(edge.group(1), set()).add(edge.group(2))
    return frames, kinds, calls


# Branches without link: ARM/Thumb relocations of B (not BL); x86 jumps.
TAIL_RELOCATIONS = {"R_ARM_THM_JUMP24", "R_ARM_THM_JUMP19", "R_ARM_THM_JUMP11", "R_ARM_THM_JUMP8",
                    "R_ARM_JUMP24"}
FUNCTION = re.compile(r"^[0-9a-f]+ <([^>]+)>:$")
INSTRUCTION = re.compile(r"^\s+[0-9a-f]+:\s+(\S+)")
RELOCATION = re.compile(r"^\s+[0-9a-f]+: (R_\S+)\s+([A-Za-z_.$][\w.$]*)")


def objdump_for(objects: list[pathlib.Path]) -> str | None:
    """arm-none-eabi-objdump for ARM objects, else the host's objdump; None when absent."""
    arm = any(o.read_bytes()[18:20] == b"\x28\x00" for o in objects[:1])  # e_machine EM_ARM
    for tool in (["arm-none-eabi-objdump"] if arm else []) + ["objdump"]:
        if shutil.which(tool):
            return tool
    return None


def load_tail_calls(directories: list[str]) -> set[tuple[str, str]]:
    """(caller, callee) pairs, named as in the .ci files, where every branch from
    the caller to the callee is a tail call (no call with link)."""
    pairs: set[tuple[str, str]] = set()
    cis = sorted(p for d in directories for p in pathlib.Path(d).rglob("*.ci"))
    objects = [o for ci in cis for o in (ci.with_suffix(".obj"), ci.with_suffix(".o")) if o.exists()]
    tool = objdump_for(objects) if objects else None
    if tool is None:
        return pairs
    for ci in cis:
        obj = next((o for o in (ci.with_suffix(".obj"), ci.with_suffix(".o")) if o.exists()), None)
        if obj is None:
            continue
        # Static functions are titled "path/file.c:name" in the .ci file.
        titles = {t.rsplit(":", 1)[-1]: t for t in NODE_TITLE.findall(ci.read_text())}
        dump = subprocess.run([tool, "-dr", "--no-show-raw-insn", str(obj)], capture_output=True,
                              text=True, check=False).stdout
        kinds: dict[tuple[str, str], set[str]] = {}
        function, mnemonic = None, ""
        for line in dump.splitlines():
            head = FUNCTION.match(line)
            if head:
                function = head.group(1)
                continue
            relocation = RELOCATION.match(line)
            if relocation and function is not None:
                kind, target = relocation.groups()
                tail = kind in TAIL_RELOCATIONS or (kind.startswith("R_X86") and mnemonic.startswith("j"))
                key = (titles.get(function, function), titles.get(target, target))
                kinds.setdefault(key, set()).add("tail" if tail else "call")
                continue
            instruction = INSTRUCTION.match(line)
            if instruction:
                mnemonic = instruction.group(1)
        pairs.update(key for key, found in kinds.items() if found == {"tail"})
    return pairs


def worst_chain(function: str, frames: dict[str, int], calls: dict[str, set[str]],
                memo: dict[str, tuple[int, list[str]]], active: list[str],
                tails: set[tuple[str, str]] = frozenset()) -> tuple[int, list[str]]:
    """Deepest (bytes, chain) below `function`; raises on recursion. A callee in
    `tails` (a tail call) runs after the caller's frame is released."""
    if function in active:
        cycle = active[active.index(function):] + [function]
        raise RecursionError(" -> ".join(cycle))
    if function in memo:
        return memo[function]
    active.append(function)
    own = frames.get(function, 0)
    best_depth, best_chain = own, [function]
    for callee in sorted(calls.get(function, ())):
        depth, chain = worst_chain(callee, frames, calls, memo, active, tails)
        if (function, callee) in tails:
            depth, chain = depth, [function, TAIL_MARK + chain[0]] + chain[1:]
        else:
            depth, chain = own + depth, [function] + chain
        if depth > best_depth or len(best_chain) == 1:
            best_depth, best_chain = depth, chain
    active.pop()
    result = (best_depth, best_chain)
    memo[function] = result
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("directories", nargs="+", help="directories searched for .ci files")
    parser.add_argument("--budget", action="append", default=[], metavar="FUNCTION=BYTES",
                        help="fail if FUNCTION's worst chain needs more than BYTES")
    parser.add_argument("--max", type=int, default=0, metavar="BYTES",
                        help="fail if any entry point's worst chain needs more than BYTES")
    parser.add_argument("--show", type=int, default=8, help="chains to print (deepest first)")
    args = parser.parse_args()

    frames, kinds, calls = load(args.directories)
    tails = load_tail_calls(args.directories)
    memo: dict[str, tuple[int, list[str]]] = {}
    status = 0
    dynamic = sorted(f for f, kind in kinds.items() if kind != "static")
    if dynamic:
        print(f"  dynamically sized frames (VLA/alloca): {', '.join(dynamic)}")
        status = 1

    # Entry points: functions defined here that nothing here calls (the API).
    called = {callee for callees in calls.values() for callee in callees}
    roots = sorted(f for f in frames if f not in called)
    rows = []
    cyclic: set[str] = set()
    # Walk every function (a cycle need not be reachable from an entry point).
    for function in roots + sorted(set(frames) - set(roots)):
        try:
            depth, chain = worst_chain(function, frames, calls, memo, [], tails)
        except RecursionError as cycle:
            members = str(cycle).split(" -> ")
            if not cyclic.intersection(members):
                print(f"  RECURSION: {cycle}")
            cyclic.update(members)
            status = 1
            continue
        if function in roots:
            unknown = [f for f in chain if f.removeprefix(TAIL_MARK) not in frames]
            rows.append((depth, function, chain, unknown))

    def short(name: str) -> str:
        mark = TAIL_MARK if name.startswith(TAIL_MARK) else ""
        return mark + name.removeprefix(mark).rsplit(":", 1)[-1]  # static functions are titled "path/file.c:name"

    for depth, function, chain, unknown in sorted(rows, key=lambda r: (-r[0], r[1]))[: args.show]:
        note = f"  (+ {', '.join(short(u) for u in unknown)}: library, not counted)" if unknown else ""
        print(f"  {depth:6d} bytes  {' -> '.join(short(c) for c in chain)}{note}")

    by_name = {function: depth for depth, function, _, _ in rows}
    if args.max > 0:
        worst = max(rows, default=(0, "-", [], []), key=lambda r: r[0])
        verdict = "ok" if worst[0] <= args.max else "EXCEEDED"
        print(f"  budget {verdict}: deepest entry point {short(worst[1])} needs {worst[0]} bytes (max {args.max})")
        if worst[0] > args.max:
            status = 1
    for budget in args.budget:
        function, _, limit = budget.partition("=")
        if function not in by_name:
            print(f"  budget: {function} not found in the call graph")
            status = 1
        elif by_name[function] > int(limit):
            print(f"  budget exceeded: {function} needs {by_name[function]} > {limit} bytes")
            status = 1
        else:
            print(f"  budget ok: {function} needs {by_name[function]} <= {limit} bytes")
    return status


if __name__ == "__main__":
    sys.exit(main())
