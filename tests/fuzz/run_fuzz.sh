#!/usr/bin/env bash
# Build and run the libFuzzer harness of the firmware API (tests/fuzz/fuzz_api.c)
# under ASan + UBSan, then write a JSON summary.
#
#   tests/fuzz/run_fuzz.sh [--runs N | --seconds S] [--jobs J] [--out DIR] [--json FILE]
#
#   --runs N      total executions, split over the jobs (make fuzz: 10^7)
#   --seconds S   instead: run for S seconds (make test's short run: 30)
#   --jobs J      parallel fuzzing processes (default: number of cores)
#   --out DIR     build and work directory (default: build/fuzz)
#   --json FILE   summary (default: build/results/fuzz.json)
#   --fail-on-indefinite  also fail when any covariance check found P not
#                 positive definite (make test's short run: the seed corpus
#                 holds inputs that did, so a regression fails the run)
#
# FUZZ_CFLAGS (environment) adds compiler flags to the harness build, e.g.
# -DPROPID_FUZZ_UPDATE_SIZED_LOADING=1 flies every input with that option.
#
# Starts from the committed seed corpus (tests/fuzz/corpus, read-only) plus the
# working corpus in DIR/corpus. Exits non-zero on any crash, sanitizer report or
# failed check (a crashing input is kept in DIR as crash-*).
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
runs=""
seconds=""
jobs=$(nproc 2>/dev/null || echo 2)
out=$repo/build/fuzz
json=$repo/build/results/fuzz.json
strict_pd=0
while [ $# -gt 0 ]; do
    case "$1" in
        --runs) runs=$2; shift 2 ;;
        --seconds) seconds=$2; shift 2 ;;
        --jobs) jobs=$2; shift 2 ;;
        --out) out=$2; shift 2 ;;
        --json) json=$2; shift 2 ;;
        --fail-on-indefinite) strict_pd=1; shift ;;
        -h|--help) sed -n '2,20p' "$0"; exit 0 ;;
        *) echo "run_fuzz.sh: unknown argument $1" >&2; exit 2 ;;
    esac
done
if [ -z "$runs" ] && [ -z "$seconds" ]; then
    runs=10000000
fi
clang=${CLANG:-clang}
if ! command -v "$clang" >/dev/null; then
    echo "run_fuzz.sh: $clang not found (Debian package clang; make setup installs it as root)" >&2
    exit 2
fi

mkdir -p "$out/corpus" "$(dirname "$json")"
sources=()
for f in "$repo"/firmware/src/propid_*.c; do
    case "$(basename "$f")" in
        propid_abi.c|propid_mavlink.c) ;;
        *) sources+=("$f") ;;
    esac
done
binary=$out/fuzz_api
"$clang" -std=c11 -g -O2 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all -DPROPID_FUZZ_CHOLESKY_ABORT=0 ${FUZZ_CFLAGS:-} \
    -I "$repo/firmware/include" "$here/fuzz_api.c" "${sources[@]}" -lm -o "$binary"

cd "$out"
rm -f fuzz-*.log crash-* leak-* timeout-*
common=(-print_final_stats=1 -max_len=1024 -timeout=30 -rss_limit_mb=2048)
start=$(date +%s)
status=0
if [ -n "$seconds" ]; then
    "$binary" "${common[@]}" -max_total_time="$seconds" corpus "$here/corpus" > fuzz-0.log 2>&1 || status=$?
    jobs=1
else
    per_job=$(( (runs + jobs - 1) / jobs ))
    pids=()
    for ((j = 0; j < jobs; ++j)); do
        "$binary" "${common[@]}" -runs="$per_job" -seed=$((1000 + j)) corpus "$here/corpus" \
            > "fuzz-$j.log" 2>&1 &
        pids+=($!)
    done
    # Progress: executions so far, from the workers' status lines.
    while kill -0 "${pids[@]}" 2>/dev/null; do
        sleep 10
        done_now=$(for ((j = 0; j < jobs; ++j)); do
                       grep -ao '^#[0-9]*' "fuzz-$j.log" 2>/dev/null | tail -1 | tr -d '#'; done |
                   awk '{s += $1} END {print s + 0}')
        printf '\rfuzz: %d / %d executions' "$done_now" "$runs" >&2
    done
    echo >&2
    for pid in "${pids[@]}"; do
        wait "$pid" || status=$?
    done
fi
elapsed=$(( $(date +%s) - start ))

python3 - "$json" "$elapsed" "$status" "$jobs" fuzz-*.log <<'EOF'
import json, re, sys
path, elapsed, status, jobs, logs = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5:]
executions = coverage = features = checks = failures = 0
crashes = 0
for log in logs:
    text = open(log, errors="replace").read()
    m = re.findall(r"stat::number_of_executed_units:\s*(\d+)", text)
    executions += int(m[-1]) if m else 0
    cov = re.findall(r"cov: (\d+) ft: (\d+)", text)
    if cov:
        coverage = max(coverage, int(cov[-1][0]))
        features = max(features, int(cov[-1][1]))
    s = re.findall(r"propid-fuzz: cholesky_checks (\d+) cholesky_failures (\d+)", text)
    if s:
        checks += int(s[-1][0])
        failures += int(s[-1][1])
    if re.search(r"ERROR: (AddressSanitizer|libFuzzer)|runtime error|propid fuzz check failed", text):
        crashes += 1
summary = {"executions": executions, "crashes": crashes, "coverage": coverage,
           "coverage_unit": "libFuzzer edge counters (cov) reached in the firmware and harness",
           "features": features, "cholesky_checks": checks, "cholesky_failures": failures,
           "jobs": jobs, "seconds": elapsed, "sanitizers": ["address", "undefined"],
           "exit_status": status}
json.dump(summary, open(path, "w"), indent=2)
print(f"fuzz: {executions} executions in {elapsed} s ({jobs} jobs), {crashes} crashes, "
      f"coverage {coverage} edges, {checks} covariance checks, {failures} not positive definite "
      f"-> {path}")
EOF
if [ "$strict_pd" -eq 1 ] && [ "$status" -eq 0 ]; then
    failures=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["cholesky_failures"])' "$json")
    if [ "$failures" -ne 0 ]; then
        echo "fuzz: FAILED: $failures covariance checks found P not positive definite" >&2
        exit 1
    fi
fi
if [ "$status" -ne 0 ]; then
    echo "fuzz: FAILED (exit $status); see $out/fuzz-*.log and crash-* inputs" >&2
    grep -ah "propid fuzz check failed\|ERROR: \|runtime error" "$out"/fuzz-*.log | head -5 >&2 || true
    exit 1
fi
