#!/usr/bin/env bash
# Fail if any object in the given Cortex-M4F archives/objects references a
# forbidden symbol: the heap (malloc/calloc/realloc/free and their newlib _r
# forms) or double precision (__aeabi_d* and __aeabi_*2d helpers, libm double
# functions). The firmware is float32-only and allocation-free.
#
#   check_symbols.sh NM FILE...                      exit 0 clean, 1 violations
#   check_symbols.sh --expect SYM... NM FILE...      self-test: exit 0 only if every
#                                                    SYM is reported as a violation
set -euo pipefail

expected=()
while [ "${1:-}" = "--expect" ]; do
    expected+=("$2")
    shift 2
done
[ $# -ge 2 ] || { echo "usage: $0 [--expect SYM]... NM FILE..." >&2; exit 2; }
nm=$1
shift

forbidden='^(malloc|calloc|realloc|free|_malloc_r|_calloc_r|_realloc_r|_free_r|memalign|aligned_alloc|posix_memalign|__aeabi_d[a-z0-9]+|__aeabi_[a-z0-9]+2d|sqrt|cbrt|hypot|sin|cos|tan|asin|acos|atan|atan2|sinh|cosh|tanh|exp|exp2|expm1|log|log2|log10|log1p|pow|floor|ceil|round|trunc|fmod|fabs|fmin|fmax|copysign|ldexp|frexp|modf)$'

violations=$(mktemp)
trap 'rm -f "$violations"' EXIT
objects=0
for file in "$@"; do
    [ -f "$file" ] || { echo "check_symbols: no such file: $file" >&2; exit 2; }
    # -A prefixes each line with archive:member (or object file).
    listing=$("$nm" -A -u "$file") || { echo "check_symbols: $nm failed on $file" >&2; exit 2; }
    objects=$((objects + $("$nm" -A "$file" 2>/dev/null | cut -d: -f1-2 | sort -u | wc -l)))
    awk -v re="$forbidden" '{ sym = $NF; if (sym ~ re) print $1 " " sym }' <<<"$listing" >> "$violations"
done

if [ ${#expected[@]} -gt 0 ]; then
    status=0
    for sym in "${expected[@]}"; do
        if grep -q " $sym\$" "$violations"; then
            echo "check_symbols self-test: caught $sym"
        else
            echo "check_symbols self-test: FAILED to catch $sym" >&2
            status=1
        fi
    done
    exit $status
fi

if [ -s "$violations" ]; then
    echo "check_symbols: forbidden symbols referenced (heap or double precision):" >&2
    sed 's/^/  /' "$violations" >&2
    exit 1
fi
echo "check_symbols: $# librar$( [ $# -eq 1 ] && echo y || echo ies ), $objects object(s): no heap, no double-precision helpers"
