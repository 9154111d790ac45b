#!/usr/bin/env bash
# Footprint of the Cortex-M4F build (called by `make target`):
#   - flash (text + data) and RAM (data + bss) of every object of the firmware
#     libraries and of the port example ELF (arm-none-eabi-size),
#   - sizeof(propid_filter_t) for PROPID_MAX_ROTORS = 4 (quad) and the default,
#   - the largest stack frames from GCC's -fstack-usage (.su) files.
#
#   footprint.sh BUILD_DIR
set -euo pipefail

build=${1:?usage: footprint.sh BUILD_DIR}
repo=$(cd "$(dirname "$0")/../.." && pwd)
size=${SIZE:-arm-none-eabi-size}
gcc=${CC:-arm-none-eabi-gcc}
nm=${NM:-arm-none-eabi-nm}
cpu_flags=(-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard)

libraries=()
for lib in "$build/firmware/libpropid.a" "$build/firmware/libpropid_quad.a" \
           "$build/firmware/mavlink/libpropid_mavlink.a"; do
    [ -f "$lib" ] && libraries+=("$lib")
done
[ ${#libraries[@]} -gt 0 ] || { echo "footprint: no firmware library in $build" >&2; exit 1; }

# `size` (Berkeley format) prints: text data bss dec hex filename
table() {
    awk -v title="$1" '
        NR == 1 { next }
        {
            name = $6; sub(/ \(ex .*\)$/, "", name); sub(/.*\//, "", name)
            flash = $1 + $2; ram = $2 + $3
            printf "  %-34s %8d %6d %6d %8d %7d\n", name, $1, $2, $3, flash, ram
            t += $1; d += $2; b += $3
        }
        END {
            printf "  %-34s %8d %6d %6d %8d %7d\n", "TOTAL " title, t, d, b, t + d, d + b
        }'
}

echo
echo "== Cortex-M4F footprint (bytes; flash = text + data, RAM = data + bss)"
printf "  %-34s %8s %6s %6s %8s %7s\n" object text data bss flash RAM
for lib in "${libraries[@]}"; do
    "$size" -B "$lib" | table "$(basename "$lib")"
done

example=$(find "$build/firmware/port" -maxdepth 1 -name '*.elf' 2>/dev/null | head -1 || true)
if [ -n "$example" ]; then
    echo
    echo "== port example ELF (vector table, start-up, newlib pieces, filter, mixer, demo board)"
    printf "  %-34s %8s %6s %6s %8s %7s\n" ELF text data bss flash RAM
    "$size" -B "$example" | table "$(basename "$example")" | awk 'NR == 1'
fi

echo
echo "== sizeof(propid_filter_t) (the caller's static RAM for one filter)"
probe=$(mktemp -d)
trap 'rm -rf "$probe"' EXIT
echo '#include "propid/propid.h"
propid_filter_t propid_footprint_probe;' > "$probe/probe.c"
for flag in -DPROPID_QUAD_BUILD=1 -DPROPID_MAX_ROTORS=4 -DPROPID_MAX_ROTORS=8; do
    "$gcc" "${cpu_flags[@]}" -std=c11 -O2 "$flag" \
        -I "$repo/firmware/include" -c "$probe/probe.c" -o "$probe/probe.o"
    bytes=$("$nm" -S --radix=d "$probe/probe.o" | awk '$4 == "propid_footprint_probe" { print $2 + 0 }')
    printf "  %-24s %d bytes\n" "${flag#-D}:" "$bytes"
done

echo
echo "== largest single stack frames of the firmware libraries (-fstack-usage)"
# Only the libraries' objects (CMake keeps them under <target>.dir), not the example.
mapfile -t su_files < <(find "$build/firmware" -name '*.su' \
    \( -path '*/propid.dir/*' -o -path '*/propid_mavlink.dir/*' \) 2>/dev/null | sort)
if [ ${#su_files[@]} -eq 0 ]; then
    echo "  no .su files (was the library built with the toolchain file?)"
else
    # line format: file:line:col:function<TAB>bytes<TAB>static|dynamic|bounded
    cat "${su_files[@]}" | awk -F'\t' '{ n = split($1, p, ":"); printf "%d\t%s\t%s\t%s:%s\n", $2, p[n], $3, p[1], p[2] }' \
        | sort -t$'\t' -k1,1nr | awk 'NR <= 5' \
        | awk -F'\t' '{ sub(/.*\//, "", $4); printf "  %6d bytes  %-36s %-8s %s\n", $1, $2, $3, $4 }'
    # The per-sample entry points (their own frames; static callees not inlined add theirs).
    entry=()
    for fn in propid_push_gyro propid_push_rotor_speeds propid_get_estimate; do
        bytes=$(cat "${su_files[@]}" | awk -F'\t' -v fn="$fn" '{ n = split($1, p, ":"); if (p[n] == fn) print $2 }')
        entry+=("$fn ${bytes:-?} B")
    done
    (IFS=';'; echo "  per-sample entry points: ${entry[*]}" | sed 's/;/, /g')
    dynamic=$(cat "${su_files[@]}" | awk -F'\t' '$3 ~ /dynamic/' | wc -l)
    echo "  frames of dynamic size (VLA/alloca): $dynamic"
fi

echo
echo "== worst-case stack of whole call chains (-fcallgraph-info; library callees not counted)"
graph_dirs=()
for dir in "$build/firmware/CMakeFiles/propid.dir" "$build/firmware/mavlink/CMakeFiles/propid_mavlink.dir"; do
    [ -d "$dir" ] && graph_dirs+=("$dir")
done
python3 "$repo/firmware/toolchain/stack_report.py" --show 4 \
    --budget propid_push_gyro=1024 --budget propid_push_rotor_speeds=1024 \
    --budget propid_get_estimate=1024 --max 2048 "${graph_dirs[@]}" || true
