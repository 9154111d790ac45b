#!/usr/bin/env bash
# `make sitl` variables: VEHICLE, TRAJECTORY, EFFECTS (comma list), MODE, SEED,
# DURATION, SENSORS reach propid_sitl as the matching options (make -n: nothing
# is built or flown). usage: test_make_sitl.sh REPO
set -u
REPO="$1"
failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }
flight() { make -n -C "$REPO" --no-print-directory sitl "$@" 2>/dev/null | grep -m1 'propid_sitl '; }

line=$(flight)
for want in "--paper" "--vehicle crazyflie-plus" "--trajectory lissajous" "--mode filter" \
            "--seed 1" "--duration 10" "--start-at-rest" "--realtime 1"; do
    [[ "$line" == *" $want "* ]] || fail "default flight lacks '$want': $line"
done
[[ "$line" == *"--effect"* ]] && fail "default flight has an effect: $line"

line=$(flight VEHICLE=hummingbird-x TRAJECTORY=circle EFFECTS=rotor_drag,esc_delay=0.01 \
       MODE=oracle SEED=7 DURATION=3 SENSORS=default)
for want in "--vehicle hummingbird-x" "--trajectory circle" "--effect rotor_drag" \
            "--effect esc_delay=0.01" "--mode oracle" "--seed 7" "--duration 3"; do
    [[ "$line" == *" $want "* ]] || fail "variables: lacks '$want': $line"
done
[[ "$line" == *"--paper"* ]] && fail "SENSORS=default still passes --paper: $line"
[ "$(grep -o -- '--vehicle' <<<"$line" | wc -l)" -eq 1 ] || fail "--vehicle given twice: $line"

if [ $failures -ne 0 ]; then
    echo "test_make_sitl.sh: $failures failure(s)"
    exit 1
fi
echo "test_make_sitl.sh: all passed"
