#!/usr/bin/env bash
# Command-line checks of propid_sitl: help, usage errors and exit codes, log
# columns (docs/flightlog.md), the vehicle file beside the log, summary JSON,
# byte-identical logs from one seed, vehicle files as input, divergence exit 3.
# usage: test_cli.sh PATH/TO/propid_sitl WORKDIR
set -u
SITL="$1"
WORK="$2"
mkdir -p "$WORK"
failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }
expect_rc() { # expected_rc description command...
    local want="$1" what="$2"; shift 2
    "$@" >"$WORK/out.txt" 2>"$WORK/err.txt"
    local rc=$?
    if [ "$rc" -ne "$want" ]; then
        fail "$what: exit $rc, expected $want"; sed 's/^/  | /' "$WORK/err.txt" | head -5
    fi
}

expect_rc 0 "--help" "$SITL" --help
grep -q -- "--vehicle" "$WORK/out.txt" || fail "--help does not list --vehicle"
grep -q "Exit codes" "$WORK/out.txt" || fail "--help does not list the exit codes"

expect_rc 2 "unknown option" "$SITL" --no-such-option
expect_rc 2 "bad mode" "$SITL" --mode sometimes
grep -q "oracle|incorrect|filter" "$WORK/err.txt" || fail "bad mode message"
expect_rc 2 "bad number" "$SITL" --duration ten
expect_rc 2 "unknown effect" "$SITL" --effect warp_drive
expect_rc 2 "unknown vehicle" "$SITL" --vehicle no-such-quad --quiet
expect_rc 2 "physics slower than control" "$SITL" --physics-rate 100 --quiet
expect_rc 2 "bad physics rate" "$SITL" --physics-rate fast --quiet
grep -q "neither auto nor a rate" "$WORK/err.txt" || fail "bad physics rate message: $(cat "$WORK/err.txt")"

# The physics step's rule (docs/sitl.md "The physics step"): the rate flown is in the summary,
# derived from the vehicle's motor time constant unless --physics-rate gives it.
physics_rate() { # summary.json -> its physics_rate_hz
    sed -n 's/.*"physics_rate_hz":[[:space:]]*\([0-9.e+]*\).*/\1/p' "$1"
}
expect_rc 0 "rule, crazyflie" "$SITL" --duration 0.1 --quiet --summary-json "$WORK/rate_cf.json"
[ "$(physics_rate "$WORK/rate_cf.json")" = "500" ] || fail "crazyflie physics rate: $(physics_rate "$WORK/rate_cf.json")"
expect_rc 0 "rule, hummingbird" "$SITL" --vehicle hummingbird-plus --duration 0.1 --quiet \
    --summary-json "$WORK/rate_hb.json"
[ "$(physics_rate "$WORK/rate_hb.json")" = "2000" ] || fail "hummingbird physics rate: $(physics_rate "$WORK/rate_hb.json")"
expect_rc 0 "rule, --motor-tau" "$SITL" --motor-tau 0.004 --physics-rate auto --duration 0.1 --quiet \
    --summary-json "$WORK/rate_tau.json"
[ "$(physics_rate "$WORK/rate_tau.json")" = "2500" ] || fail "tau 4 ms physics rate: $(physics_rate "$WORK/rate_tau.json")"
expect_rc 0 "given physics rate" "$SITL" --physics-rate 2000 --duration 0.1 --quiet \
    --summary-json "$WORK/rate_given.json"
[ "$(physics_rate "$WORK/rate_given.json")" = "2000" ] || fail "given physics rate: $(physics_rate "$WORK/rate_given.json")"

# Steps across ESC reports (docs/sitl.md "The loop"): a report whose reading (its instant less
# the latency) is already in the history is handled at the step's end with the same reading.
# Exact readings (no loss, no quantisation): the reported speeds (columns 5-8) of the flight
# with a step ending at every report and of the default loop agree to the closed loop's
# rounding-level spread (measured 5e-3 rad/s), not the ~ 1 rad/s a reading taken at the wrong
# instant would move them; without latency no report can be read from the history, so the
# two loops fly the same flight.
exact_esc="--esc-dropout 0 --esc-quantisation none"
expect_rc 0 "ESC split steps" "$SITL" --duration 10 --quiet $exact_esc --esc-split-steps --log "$WORK/split.csv"
expect_rc 0 "ESC steps across" "$SITL" --duration 10 --quiet $exact_esc --log "$WORK/across.csv"
worst=$(paste -d, "$WORK/split.csv" "$WORK/across.csv" | awk -F, 'NR > 2 && $5 != "" {
    n = NF / 2; for (i = 5; i <= 8; i++) { d = $i - $(i + n); if (d < 0) d = -d; if (d > m) m = d } }
    END { printf "%.6f", m + 0 }')
awk -v w="$worst" 'BEGIN { exit !(w > 0 && w < 0.05) }' || fail "reported speeds across ESC instants differ by $worst rad/s"
expect_rc 0 "ESC split steps, no latency" "$SITL" --duration 2 --quiet --esc-latency 0 --esc-split-steps \
    --log "$WORK/split0.csv"
expect_rc 0 "ESC steps across, no latency" "$SITL" --duration 2 --quiet --esc-latency 0 --log "$WORK/across0.csv"
cmp -s "$WORK/split0.csv" "$WORK/across0.csv" || fail "without latency the loop stepped across an ESC report"

# IMU samples inside a physics step (read from the step's stages, docs/sitl.md "The loop"):
# with exact sensors and a 1 kHz gyro at the 500 Hz physics step, the flights with a step
# ending at every sample and of the default loop agree to the closed loop's rounding floor
# (measured: true body rate 4.7e-6 rad/s), not the ~ 4e-2 rad/s of a sample read at the
# step's end instead of its instant; they are not the same bytes (the default loop crossed).
expect_rc 0 "IMU split steps" "$SITL" --duration 10 --quiet --paper --imu-rate 1000 --imu-split-steps \
    --log "$WORK/imu_split.csv"
expect_rc 0 "IMU steps across" "$SITL" --duration 10 --quiet --paper --imu-rate 1000 --log "$WORK/imu_across.csv"
worst=$(paste -d, "$WORK/imu_split.csv" "$WORK/imu_across.csv" | awk -F, '
    /^#/ { next }
    !cols { n = NF / 2; for (i = 1; i <= n; i++) if ($i ~ /^true_w[xyz]$/) c[++cols] = i; next }
    { for (k = 1; k <= cols; k++) { d = $(c[k]) - $(c[k] + n); if (d < 0) d = -d; if (d > m) m = d } }
    END { printf "%.9f", m + 0 }')
awk -v w="$worst" 'BEGIN { exit !(w > 0 && w < 1e-4) }' || fail "true body rates across IMU instants differ by $worst rad/s"
# Two samples inside one physics step (a 2 kHz gyro at 500 Hz physics): the step splits at
# the first, so every sample reaches the filter (2 s: 4000), as with a step ending at each.
gyro_accepted() {
    sed -n 's/.*"gyro_accepted":[[:space:]]*\([0-9]*\).*/\1/p' "$1"
}
for rate in 2000 700; do
    expect_rc 0 "IMU at $rate Hz" "$SITL" --duration 2 --quiet --imu-rate $rate --summary-json "$WORK/imu_$rate.json"
    expect_rc 0 "IMU at $rate Hz, split" "$SITL" --duration 2 --quiet --imu-rate $rate --imu-split-steps \
        --summary-json "$WORK/imu_split_$rate.json"
    [ "$(gyro_accepted "$WORK/imu_$rate.json")" = "$(gyro_accepted "$WORK/imu_split_$rate.json")" ] &&
        [ "$(gyro_accepted "$WORK/imu_$rate.json")" = "$((2 * rate))" ] ||
        fail "IMU at $rate Hz: $(gyro_accepted "$WORK/imu_$rate.json") gyro samples accepted, split loop $(gyro_accepted "$WORK/imu_split_$rate.json")"
done

cat >"$WORK/nomass.vehicle.json" <<'JSON'
{"name": "x", "mass": null, "inertia": [1e-3, 1e-3, 2e-3],
 "rotors": [{"position": [0.1, 0, 0], "yaw_sign": 1}], "kf_nominal": 1e-6, "km_nominal": 1e-8}
JSON
expect_rc 2 "vehicle file without mass" "$SITL" --vehicle "$WORK/nomass.vehicle.json" --quiet
grep -q "'mass' is missing or null" "$WORK/err.txt" || fail "missing-mass message: $(cat "$WORK/err.txt")"
# An inertia that is symmetric but not positive definite is a bad vehicle file (exit 2),
# named before the flight (it was the filter's set-up failing, exit 1, in every mode).
cat >"$WORK/notspd.vehicle.json" <<'JSON'
{"name": "x", "mass": 0.5, "inertia": [[1e-3, 5e-3, 0], [5e-3, 1e-3, 0], [0, 0, 2e-3]],
 "rotors": [{"position": [0.1, 0, 0], "yaw_sign": 1}, {"position": [0, 0.1, 0], "yaw_sign": -1},
            {"position": [-0.1, 0, 0], "yaw_sign": 1}, {"position": [0, -0.1, 0], "yaw_sign": -1}],
 "kf_nominal": 1e-6, "km_nominal": 1e-8}
JSON
expect_rc 2 "vehicle file with an inertia not positive definite" "$SITL" \
    --vehicle "$WORK/notspd.vehicle.json" --mode oracle --quiet
grep -q "inertia must be positive definite" "$WORK/err.txt" || fail "inertia message: $(cat "$WORK/err.txt")"

# A logged flight, twice with the same seed, once with another.
expect_rc 0 "logged flight" "$SITL" --trajectory circle --seed 7 --duration 10 --quiet \
    --log "$WORK/a.csv" --summary-json "$WORK/a.json"
grep -q "tracking RMSE" "$WORK/out.txt" || fail "no final summary"
expect_rc 0 "logged flight again" "$SITL" --trajectory circle --seed 7 --duration 10 --quiet \
    --log "$WORK/b.csv"
cmp -s "$WORK/a.csv" "$WORK/b.csv" || fail "same seed gave different logs"
expect_rc 0 "other seed" "$SITL" --trajectory circle --seed 8 --duration 10 --quiet --log "$WORK/c.csv"
cmp -s "$WORK/a.csv" "$WORK/c.csv" && fail "different seeds gave the same log"

header=$(head -1 "$WORK/a.csv")
expected="t,gyro_x,gyro_y,gyro_z,omega_1,omega_2,omega_3,omega_4,acc_x,acc_y,acc_z,qw,qx,qy,qz,vx,vy,vz,px,py,pz,cmd_1,cmd_2,cmd_3,cmd_4,ref_px,ref_py,ref_pz,ref_yaw,true_kf_1,true_kf_2,true_kf_3,true_kf_4,true_km_1,true_km_2,true_km_3,true_km_4,true_bg_x,true_bg_y,true_bg_z,true_wx,true_wy,true_wz,est_kf_1,std_kf_1,est_kf_2,std_kf_2,est_kf_3,std_kf_3,est_kf_4,std_kf_4,est_km_1,std_km_1,est_km_2,std_km_2,est_km_3,std_km_3,est_km_4,std_km_4,est_bg_x,est_bg_y,est_bg_z,std_bg_x,std_bg_y,std_bg_z,est_wx,est_wy,est_wz,health,status,true_omega_1,true_omega_2,true_omega_3,true_omega_4"
[ "$header" = "$expected" ] || fail "log header differs from the contract: $header"
rows=$(($(wc -l <"$WORK/a.csv") - 1))
[ "$rows" -eq 5001 ] || fail "expected 5001 rows at 500 Hz for 10 s, got $rows"
cols=$(echo "$header" | tr ',' '\n' | wc -l)
bad=$(awk -F, -v n="$cols" 'NR > 1 && NF != n {c++} END {print c + 0}' "$WORK/a.csv")
[ "$bad" -eq 0 ] || fail "$bad rows with the wrong field count"
[ -f "$WORK/a.vehicle.json" ] || fail "no a.vehicle.json beside the log"

if command -v python3 >/dev/null; then
    python3 - "$WORK" <<'PY' || fail "vehicle/summary JSON check"
import json, sys
w = sys.argv[1]
v = json.load(open(w + "/a.vehicle.json"))
assert v["mass"] == 0.03 and len(v["rotors"]) == 4, v
assert v["kf_nominal"] == 2.3e-8 and v["km_nominal"] == 7.8e-10, v
assert v["rotors"][0]["position"] == [0.043, 0, 0] and v["rotors"][1]["yaw_sign"] == -1, v
s = json.load(open(w + "/a.json"))
assert s["stable"] is True and s["exit_code"] == 0 and s["trajectory"] == "circle", s
assert 0 < s["rmse_x_m"] < 0.05, s
PY
fi

# The written vehicle file flies.
expect_rc 0 "vehicle from file" "$SITL" --vehicle "$WORK/a.vehicle.json" --trajectory hover \
    --mode oracle --duration 2 --quiet
# The log's vehicle file says what the input said: a rotor inertia the simulator assumed from
# the radius for its effects (the input has none) is written null, named in the notes; the
# input's own value is kept (propid replay models a written value by default).
if command -v python3 >/dev/null; then
    python3 - "$WORK" <<'PY' || fail "radius-only vehicle file"
import json, sys
w = sys.argv[1]
v = json.load(open(w + "/a.vehicle.json"))
v.pop("notes")
for name, inertia in (("r_null", None), ("r_given", 6e-6)):
    json.dump(dict(v, name=name, rotor_radius=0.0635, rotor_inertia=inertia), open(f"{w}/{name}.json", "w"))
PY
    for name in r_null r_given; do
        expect_rc 0 "vehicle file $name" "$SITL" --vehicle "$WORK/$name.json" --trajectory hover \
            --mode oracle --duration 0.2 --quiet --log "$WORK/$name.csv"
    done
    python3 - "$WORK" <<'PY' || fail "the log's vehicle file keeps the input's rotor inertia"
import json, sys
w = sys.argv[1]
v = json.load(open(w + "/r_null.vehicle.json"))
assert v["rotor_radius"] == 0.0635 and v["rotor_inertia"] is None, v
assert "rotor inertia not in the vehicle file (null)" in v["notes"], v["notes"]
v = json.load(open(w + "/r_given.vehicle.json"))
assert v["rotor_inertia"] == 6e-6 and "assumed" not in v["notes"], v
PY
fi
# A short flight flies the start of the same 10 s trajectory (the period is not
# the duration): a 2 s Lissajous used to be 5x faster and diverged at 0.4 s.
expect_rc 0 "short lissajous" "$SITL" --trajectory lissajous --mode filter --duration 2 --quiet
expect_rc 3 "lissajous squeezed into 2 s diverges" "$SITL" --trajectory lissajous --mode filter \
    --duration 2 --trajectory-period 2 --quiet
expect_rc 2 "bad period" "$SITL" --trajectory-period 0
# Paper sensors and effects parse and fly.
expect_rc 0 "paper + effects" "$SITL" --paper --effect rotor_drag --effect esc_delay=0.01 \
    --duration 10 --quiet --log-rate 100 --log "$WORK/p.csv"
rows=$(($(wc -l <"$WORK/p.csv") - 1))
[ "$rows" -eq 1001 ] || fail "--log-rate 100: expected 1001 rows, got $rows"

# Divergence: exit 3 with a message, log kept.
expect_rc 3 "divergence" "$SITL" --vehicle hummingbird-plus --mode oracle --motor-tau 0.3 \
    --quiet --log "$WORK/d.csv"
grep -q "diverged" "$WORK/err.txt" || fail "no divergence message"
[ "$(wc -l <"$WORK/d.csv")" -gt 100 ] || fail "divergence log too short"

# The filter's optional terms: a configuration the library refuses names its field
# (exit 1); a telemetry delay held by the filter removes the bias the delay causes.
expect_rc 1 "torque scale without the accelerometer" "$SITL" --duration 1 --quiet --filter-torque-scale
grep -q "field 'torque_scale'" "$WORK/err.txt" || fail "torque-scale message: $(cat "$WORK/err.txt")"
expect_rc 1 "delay beyond the filter's buffer" "$SITL" --duration 1 --quiet --filter-esc-delay 0.5
grep -q "field 'rotor_delay_us'" "$WORK/err.txt" || fail "delay message: $(cat "$WORK/err.txt")"
expect_rc 0 "every optional term" "$SITL" --duration 2 --quiet --filter-disturbance --filter-accel \
    --filter-torque-scale --filter-rotor-inertia --filter-esc-delay 0.001 --summary-json "$WORK/opt.json"
for held in 0 0.02; do
    expect_rc 0 "esc_delay effect, filter delay $held" "$SITL" --paper --vehicle crazyflie-x --trajectory step \
        --duration 6 --quiet --effect esc_delay --filter-esc-delay "$held" --summary-json "$WORK/delay_$held.json"
done
if command -v python3 >/dev/null; then
    python3 - "$WORK" <<'PY' || fail "telemetry delay: held vs not held"
import json, sys
w = sys.argv[1]
opt = json.load(open(w + "/opt.json"))
assert opt["stable"] and opt["gyro_accepted"] > 1900, opt
off, on = (json.load(open(f"{w}/delay_{d}.json"))["kf_rel_error_max"] for d in ("0", "0.02"))
print(f"esc_delay 20 ms: max |kf/kf_true - 1| {off:.4f} not held, {on:.4f} held")
assert on < 0.01 < 0.1 < off, (off, on)
PY
fi

# Output paths: missing directories are created (as the host tools do); a
# path that cannot be written fails before the flight, in one line.
rm -rf "$WORK/new"
expect_rc 0 "log and summary into missing directories" "$SITL" --duration 1 --quiet \
    --log "$WORK/new/logs/n.csv" --summary-json "$WORK/new/json/n.json"
[ -f "$WORK/new/logs/n.csv" ] && [ -f "$WORK/new/logs/n.vehicle.json" ] || fail "log not written into a new directory"
[ -f "$WORK/new/json/n.json" ] || fail "summary not written into a new directory"
: >"$WORK/blocker"
for target in "--summary-json $WORK/blocker/s.json" "--log $WORK/blocker/deeper/l.csv" "--summary-json $WORK"; do
    # shellcheck disable=SC2086
    expect_rc 1 "unwritable output $target" "$SITL" --duration 60 --quiet $target
    grep -q "tracking RMSE" "$WORK/out.txt" && fail "$target: flew before refusing"
    [ "$(wc -l <"$WORK/err.txt")" -eq 1 ] || fail "$target: message is not one line: $(cat "$WORK/err.txt")"
    grep -q "cannot write" "$WORK/err.txt" || fail "$target: message: $(cat "$WORK/err.txt")"
done
[ -e "$WORK/blocker/deeper" ] && fail "refused output left a directory behind"

# MAVLink: flies when the link is built in, otherwise a clear usage error.
"$SITL" --duration 10 --quiet --mavlink udp:127.0.0.1:14599 >"$WORK/out.txt" 2>"$WORK/err.txt"
rc=$?
if [ $rc -ne 0 ] && ! { [ $rc -eq 2 ] && grep -q "without the MAVLink link" "$WORK/err.txt"; }; then
    fail "--mavlink: exit $rc"; head -3 "$WORK/err.txt"
fi

if [ $failures -ne 0 ]; then
    echo "test_cli.sh: $failures failure(s)"
    exit 1
fi
echo "test_cli.sh: all passed"
