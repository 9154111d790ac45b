#!/usr/bin/env python3
"""Count the instructions of each counted step in a QEMU `-d exec,nochain` trace.

    count_trace.py TRACE SYMS RAW_JSON            (while QEMU runs)
    count_trace.py --report RAW_JSON QEMU_STDOUT [JSON]   (after it exited)

TRACE is read as it is written (a pipe): one line per executed instruction with
its PC. SYMS is `nm` output (address name) of the ELF's functions. A variant
starts at each call of propid_count_variant(); instructions between
propid_count_begin() and propid_count_end() are one step (the markers and the
harness itself excluded). Labels of the variants come from the harness's
"variant LABEL" lines on QEMU's stdout. Prints median/min/max per variant and
the mean instructions per step of each function (self); JSON gets the same.
"""

import bisect
import collections
import json
import re
import statistics
import sys


def count(trace_path: str, syms_path: str, raw_path: str) -> int:
    syms = sorted((int(a, 16) & ~1, n) for a, n in (line.split() for line in open(syms_path)))
    addrs = [a for a, _ in syms]
    by_name = {n: a for a, n in syms}
    names: dict[int, str] = {}

    def symbol(pc: int) -> str:
        if pc not in names:
            i = bisect.bisect_right(addrs, pc) - 1
            names[pc] = syms[i][1] if i >= 0 else "?"
        return names[pc]

    begin, end = by_name["propid_count_begin"], by_name["propid_count_end"]
    marker = by_name["propid_count_variant"]
    harness = {"propid_count_begin", "propid_count_end", "propid_count_variant", "fly", "main"}
    pc_re = re.compile(rb"\[[0-9a-f]+/([0-9a-f]+)/")
    variant = -1
    counting = False
    steps_in_step = 0
    steps: dict[int, list[int]] = collections.defaultdict(list)
    per_fn: dict[int, collections.Counter] = collections.defaultdict(collections.Counter)
    with open(trace_path, "rb") as trace:
        for line in trace:
            m = pc_re.search(line)
            if not m:
                continue
            pc = int(m.group(1), 16)
            if pc == marker:
                variant += 1
            elif pc == begin:
                counting, steps_in_step = True, 0
            elif pc == end:
                if counting:
                    steps[variant].append(steps_in_step)
                counting = False
            elif counting:
                name = symbol(pc)
                if name not in harness:
                    steps_in_step += 1
                    per_fn[variant][name] += 1
    raw = [{"steps": steps[v], "per_function": dict(per_fn[v])} for v in sorted(steps)]
    with open(raw_path, "w") as f:
        json.dump(raw, f)
    return 0


def report(raw_path: str, stdout_path: str, json_path: str) -> int:
    raw = json.load(open(raw_path))
    output = open(stdout_path).read()
    labels = [line.split(None, 1)[1].strip() for line in output.splitlines()
              if line.startswith("variant ")]
    result: dict = {"variants": {}, "harness_output": output.splitlines()}
    for v, data in enumerate(raw):
        s = data["steps"]
        label = labels[v] if v < len(labels) else str(v)
        per_fn = sorted(data["per_function"].items(), key=lambda kv: -kv[1])
        result["variants"][label] = {
            "median": statistics.median(s), "min": min(s), "max": max(s), "steps": len(s),
            "per_function": {n: round(c / len(s), 1) for n, c in per_fn},
        }
        print(f"{label}: {statistics.median(s):.0f} instructions per gyro step "
              f"(median; min {min(s)}, max {max(s)}, {len(s)} steps)")
        for name, c in per_fn[:8]:
            print(f"    {c / len(s):8.1f}  {name}")
    print(output, end="")
    m = re.search(r"max_state_diff_in_std (\S+)", output)
    if m:
        result["dense_max_state_diff_in_std"] = float(m.group(1))
    if json_path:
        with open(json_path, "w") as f:
            json.dump(result, f, indent=1)
    return 0


def main() -> int:
    if sys.argv[1] == "--report":
        return report(sys.argv[2], sys.argv[3], sys.argv[4] if len(sys.argv) > 4 else "")
    return count(sys.argv[1], sys.argv[2], sys.argv[3])


if __name__ == "__main__":
    sys.exit(main())
