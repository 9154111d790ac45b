#!/usr/bin/env bash
# Instructions per filter step on the Cortex-M4 instruction set (benchmark, not a test).
#
#   tests/qemu/count_step.sh [--src DIR] [--json FILE] [OUT_DIR]
#
# Builds tests/qemu/count_step.c (+ dense_ekf.c, the dense baseline) with the firmware
# filter sources (from DIR/firmware, default: this repository; pass another checkout
# to measure an older version) using the target build's flags (-O2, Cortex-M4F hard
# float, -ffp-contract=fast; extra flags in COUNT_STEP_CFLAGS, e.g.
# -DPROPID_MAX_ROTORS=4), runs it under qemu-system-arm -M mps2-an386 with
# `-singlestep -d exec,nochain` (one trace line per executed instruction, streamed
# through a pipe; the harness's semihosting console arrives on QEMU's stderr) and
# counts the instructions executed between propid_count_begin() and
# propid_count_end(), i.e. inside each counted gyro step including its callees.
# Prints, per variant (quad plus, quad X, hexa, octo, dense baseline on the quad),
# median/min/max instructions per step and the mean per function (self); --json
# writes the same. Optional terms: -DCOUNT_STEP_DISTURBANCE, -DCOUNT_STEP_ROTOR_INERTIA=J,
# -DCOUNT_STEP_AERO_DAMPING=D,
# -DCOUNT_STEP_DELAY_US=D, -DCOUNT_STEP_INPUT_NOISE=S (+ -DCOUNT_STEP_INPUT_COMPENSATION), -DCOUNT_STEP_REPORT_TIMING=T, -DCOUNT_STEP_ACCEL (+ -DCOUNT_STEP_ACCEL_ERROR) in COUNT_STEP_CFLAGS; -DCOUNT_STEP_GET_ESTIMATE counts propid_get_estimate() after each step instead. QEMU does not model cycles: these are
# instruction counts.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
src=$repo
json=""
while [ $# -gt 0 ]; do
    case "$1" in
        --src) src=$(cd "$2" && pwd); shift 2 ;;
        --json) json=$2; shift 2 ;;
        -h|--help) sed -n '2,19p' "$0"; exit 0 ;;
        *) break ;;
    esac
done
out=${1:-$repo/build/bench}
mkdir -p "$out"

gcc=${CC_ARM:-arm-none-eabi-gcc}
cpu=(-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard)
# shellcheck disable=SC2206
extra=(${COUNT_STEP_CFLAGS:-})
cflags=("${cpu[@]}" -std=c11 -O2 -DNDEBUG -fno-math-errno -ffp-contract=fast
        -ffunction-sections -fdata-sections "${extra[@]}")

# The quad build's library leaves out the damage detector and the model helpers
# (firmware/CMakeLists.txt): they need the general build's derived data.
quad_build=0
case " ${extra[*]:-} " in *" -DPROPID_QUAD_BUILD=1 "*) quad_build=1 ;; esac
sources=()
for f in "$src"/firmware/src/propid_*.c; do
    case "$(basename "$f")" in
        propid_abi.c|propid_mavlink.c) ;;   # host-only / separate library
        propid_damage.c|propid_model.c) [ "$quad_build" = 1 ] || sources+=("$f") ;;
        *) sources+=("$f") ;;
    esac
done

# The size-lean quad build compiles these for size on the target
# (firmware/CMakeLists.txt, PROPID_SIZE_LEAN_OS_SOURCES): counted as built.
lean_objects=()
case " ${extra[*]:-} " in
    *" -DPROPID_SIZE_LEAN=1 "*)
        kept=()
        for f in "${sources[@]}"; do
            case "$(basename "$f")" in
                propid_predict.c|propid_filter.c|propid_estimate.c|propid_coeff_basis.c)
                    object="$out/$(basename "$f" .c).os.o"
                    "$gcc" "${cflags[@]}" -Os -I "$src/firmware/include" -I "$src/firmware/src" -I "$here" \
                        -c "$f" -o "$object"
                    lean_objects+=("$object") ;;
                *) kept+=("$f") ;;
            esac
        done
        sources=("${kept[@]}") ;;
esac

elf="$out/count_step.elf"
"$gcc" "${cflags[@]}" -I "$src/firmware/include" -I "$src/firmware/src" -I "$here" \
    "${sources[@]}" ${lean_objects[@]+"${lean_objects[@]}"} "$here/count_step.c" "$here/dense_ekf.c" "$here/startup.c" \
    "$here/semihosting.c" "$here/stack_watermark.c" \
    -nostartfiles --specs=nano.specs --specs=nosys.specs -L "$here" -T "$here/mps2_an386.ld" \
    -Wl,--gc-sections -lm -o "$elf"

nm=${NM_ARM:-arm-none-eabi-nm}
"$nm" "$elf" | awk '$2 ~ /^[tT]$/ { print $1, $3 }' > "$out/count_step.syms"

# The trace (tens of millions of lines with the dense baseline) goes through a pipe.
fifo="$out/count_step.trace"
rm -f "$fifo"
mkfifo "$fifo"
trap 'rm -f "$fifo"' EXIT
qemu-system-arm -M mps2-an386 -nographic -monitor none -serial none \
    -semihosting-config enable=on,target=native \
    -singlestep -d exec,nochain -D "$fifo" -kernel "$elf" > "$out/count_step.out" 2>&1 &
qemu=$!

python3 "$here/count_trace.py" "$fifo" "$out/count_step.syms" "$out/count_step.raw.json"
qemu_status=0
wait "$qemu" || qemu_status=$?
python3 "$here/count_trace.py" --report "$out/count_step.raw.json" "$out/count_step.out" "$json"
if [ "$qemu_status" -ne 0 ]; then
    echo "count_step: the harness reported failures (exit $qemu_status)" >&2
    exit 1
fi
