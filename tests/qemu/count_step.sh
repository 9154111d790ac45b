#!/usr/bin/env bash
# Instructions per filter step on the Cortex-M4 instruction set (benchmark, not a test).
#
#   tests/qemu/count_step.sh [--src DIR] [--keep] [OUT_DIR]
#
# Builds tests/qemu/count_step.c with the firmware filter sources (from DIR/firmware,
# default: this repository; pass another checkout to measure an older version)
# using the target build's flags (-O2, Cortex-M4F hard float, -ffp-contract=fast),
# runs it under qemu-system-arm -M mps2-an386 with `-singlestep -d exec,nochain`
# (one trace line per executed instruction) and counts the instructions executed
# between propid_count_begin() and propid_count_end(), i.e. inside each counted
# propid_push_gyro() call including its callees. Prints, per variant (quad plus
# frame and quad X frame, diagonal inertia), mean/min/max instructions per step
# over the counted steps and the mean per function (self, not inclusive).
# QEMU does not model cycles: these are instruction counts.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
src=$repo
keep=0
while [ $# -gt 0 ]; do
    case "$1" in
        --src) src=$(cd "$2" && pwd); shift 2 ;;
        --keep) keep=1; shift ;;
        -h|--help) sed -n '2,15p' "$0"; exit 0 ;;
        *) break ;;
    esac
done
out=${1:-$repo/build/bench}
mkdir -p "$out"

gcc=${CC_ARM:-arm-none-eabi-gcc}
cpu=(-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard)
cflags=("${cpu[@]}" -std=c11 -O2 -DNDEBUG -fno-math-errno -ffp-contract=fast
        -ffunction-sections -fdata-sections)

sources=()
for f in "$src"/firmware/src/propid_*.c; do
    case "$(basename "$f")" in
        propid_abi.c|propid_mavlink.c) ;;   # host-only / separate library
        *) sources+=("$f") ;;
    esac
done

elf="$out/count_step.elf"
"$gcc" "${cflags[@]}" -I "$src/firmware/include" -I "$here" \
    "${sources[@]}" "$here/count_step.c" "$here/startup.c" "$here/semihosting.c" \
    "$here/stack_watermark.c" \
    -nostartfiles --specs=nano.specs --specs=nosys.specs -L "$here" -T "$here/mps2_an386.ld" \
    -Wl,--gc-sections -lm -o "$elf"

nm=${NM_ARM:-arm-none-eabi-nm}
"$nm" "$elf" | awk '$2 ~ /^[tT]$/ { print $1, $3 }' > "$out/count_step.syms"

trace="$out/count_step.trace"
qemu-system-arm -M mps2-an386 -nographic -monitor none -serial none \
    -semihosting-config enable=on,target=native \
    -singlestep -d exec,nochain -D "$trace" -kernel "$elf"

python3 - "$trace" "$out/count_step.syms" <<'EOF'
import bisect, collections, re, sys
trace_path, syms_path = sys.argv[1], sys.argv[2]
syms = sorted((int(a, 16) & ~1, n) for a, n in (l.split() for l in open(syms_path)))
addrs = [a for a, _ in syms]
by_name = {n: a for a, n in syms}
names = {}
def symbol(pc):
    if pc not in names:
        i = bisect.bisect_right(addrs, pc) - 1
        names[pc] = syms[i][1] if i >= 0 else "?"
    return names[pc]
begin, end, init = by_name["propid_count_begin"], by_name["propid_count_end"], by_name["propid_init"]
harness = {"propid_count_begin", "propid_count_end", "fly", "main"}
pc_re = re.compile(r"\[[0-9a-f]+/([0-9a-f]+)/")
variant = -1          # advanced by each propid_init: 0 = plus, 1 = X
counting = False
steps = collections.defaultdict(list)
per_fn = collections.defaultdict(collections.Counter)
for line in open(trace_path):
    m = pc_re.search(line)
    if not m:
        continue
    pc = int(m.group(1), 16)
    if pc == init:
        variant += 1
    elif pc == begin:
        counting, count = True, 0
    elif pc == end:
        if counting:
            steps[variant].append(count)
        counting = False
    elif counting:
        name = symbol(pc)
        if name not in harness:
            count += 1
            per_fn[variant][name] += 1
labels = {0: "quad plus frame (diag J)", 1: "quad X frame (diag J)"}
for v in sorted(steps):
    s = steps[v]
    print(f"{labels.get(v, v)}: {sum(s) / len(s):.0f} instructions per gyro step "
          f"(min {min(s)}, max {max(s)}, {len(s)} steps)")
    for name, c in per_fn[v].most_common():
        print(f"    {c / len(s):8.1f}  {name}")
EOF
[ "$keep" = 1 ] || rm -f "$trace"
