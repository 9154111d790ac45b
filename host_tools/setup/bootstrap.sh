#!/usr/bin/env bash
# Set-up a fresh Debian machine needs for propid. Idempotent; the Makefile calls
# one step at a time and keeps stamp files so repeated `make` calls are fast.
#
#   bootstrap.sh apt      Debian packages (installed when missing and root)
#   bootstrap.sh venv     .venv with the pinned requirements + editable host_tools
#   bootstrap.sh unity    Unity C sources from the vyperling wheel, hash checked
#   bootstrap.sh all      the three in order
#
# Environment:
#   PYTHON                    interpreter for the venv (default python3)
#   PROPID_APT_PRETEND_MISSING  space-separated packages to treat as missing
#                             (tests the install path without uninstalling)
#   PROPID_APT_DRY_RUN=1      print the apt-get commands instead of running them
set -euo pipefail

repo=$(cd "$(dirname "$0")/../.." && pwd)
cd "$repo"

PYTHON=${PYTHON:-python3}
venv="$repo/.venv"
deps="$repo/build/_deps"

# Unity: ThrowTheSwitch Unity v2.6.1 sources, as shipped inside this wheel.
unity_pin="vyperling==0.0.4"
unity_sha256="028f4419cf4f49cfaed51256290718753a78cc035923fbf43acc8bcd62d205cb"

apt_packages=(cmake gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm libcjson-dev
              clang libclang-rt-dev cppcheck)

say() { printf 'bootstrap: %s\n' "$*"; }
die() { printf 'bootstrap: error: %s\n' "$*" >&2; exit 1; }

is_installed() {
    local pkg=$1
    case " ${PROPID_APT_PRETEND_MISSING:-} " in *" $pkg "*) return 1 ;; esac
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed'
}

# `python3 -m venv` needs ensurepip, which Debian ships in python3-venv.
python_can_make_venv() {
    case " ${PROPID_APT_PRETEND_MISSING:-} " in *" python3-venv "*) return 1 ;; esac
    "$PYTHON" -c 'import venv, ensurepip' >/dev/null 2>&1
}

step_apt() {
    command -v dpkg-query >/dev/null 2>&1 || die "dpkg-query not found: this set-up expects Debian (install ${apt_packages[*]} by hand)"
    local missing=() pkg
    for pkg in "${apt_packages[@]}"; do
        is_installed "$pkg" || missing+=("$pkg")
    done
    command -v "$PYTHON" >/dev/null 2>&1 || missing+=(python3)
    if command -v "$PYTHON" >/dev/null 2>&1 && ! python_can_make_venv; then
        missing+=(python3-venv)
    fi
    if [ ${#missing[@]} -eq 0 ]; then
        say "apt packages present: ${apt_packages[*]}"
        return 0
    fi
    if [ "$(id -u)" -ne 0 ]; then
        die "missing Debian packages: ${missing[*]}
  install them as root:  sudo apt-get update && sudo apt-get install -y ${missing[*]}"
    fi
    say "installing missing Debian packages: ${missing[*]}"
    if [ "${PROPID_APT_DRY_RUN:-0}" = 1 ]; then
        echo "apt-get update"
        echo "DEBIAN_FRONTEND=noninteractive apt-get install -y ${missing[*]}"
        return 0
    fi
    apt_waiting_for_lock update
    DEBIAN_FRONTEND=noninteractive apt_waiting_for_lock install -y "${missing[@]}"
}

# A fresh machine often runs another apt at boot (unattended upgrades), and several checkouts set up at
# once: wait for apt's locks (up to 10 min) instead of failing on them. `update` does not honour
# DPkg::Lock::Timeout for the lists lock, hence the retries.
apt_waiting_for_lock() {
    local attempt log
    log=$(mktemp)
    for attempt in $(seq 1 120); do
        if apt-get -o DPkg::Lock::Timeout=5 "$@" >"$log" 2>&1; then
            cat "$log"; rm -f "$log"; return 0
        fi
        cat "$log"
        grep -q "Could not get lock" "$log" || { rm -f "$log"; die "apt-get $* failed"; }
        say "apt is locked by another process; waiting (attempt $attempt of 120)"
        sleep 5
    done
    rm -f "$log"
    die "apt-get $*: apt stayed locked for 10 minutes"
}

step_venv() {
    local req="$repo/host_tools/setup/requirements.txt"
    if [ ! -x "$venv/bin/python" ]; then
        say "creating $venv with $PYTHON"
        "$PYTHON" -m venv "$venv" || die "'$PYTHON -m venv' failed (Debian: apt-get install python3-venv)"
    fi
    say "installing pinned requirements (hash checked)"
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
        --require-hashes --only-binary=:all: -r "$req"
    say "installing host_tools (editable)"
    # (setuptools' generic "editable installation" warning is noise here)
    PYTHONWARNINGS=ignore "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
        --no-deps --no-build-isolation -e "$repo/host_tools"
    [ -x "$venv/bin/propid" ] || die "$venv/bin/propid missing after the editable install"
    "$venv/bin/python" -m pip check >/dev/null || die "pip check found inconsistent requirements in $venv"
}

step_unity() {
    local wheels="$deps/wheels" out="$deps/unity" pin_file="$deps/unity-requirements.txt"
    local py="$venv/bin/python"
    [ -x "$py" ] || py=$PYTHON
    mkdir -p "$wheels"
    printf '%s --hash=sha256:%s\n' "$unity_pin" "$unity_sha256" > "$pin_file"
    say "fetching Unity ($unity_pin, sha256 checked)"
    "$py" -m pip download --quiet --disable-pip-version-check --no-deps \
        --require-hashes --only-binary=:all: -r "$pin_file" -d "$wheels"
    local wheel="$wheels/vyperling-0.0.4-py3-none-any.whl"
    [ -f "$wheel" ] || die "pip did not leave $wheel"
    # Check the hash again ourselves: a stale file in the cache dir must not pass.
    echo "$unity_sha256  $wheel" | sha256sum --check --quiet - || die "sha256 mismatch for $wheel"
    rm -rf "$out.tmp"
    mkdir -p "$out.tmp"
    "$py" - "$wheel" "$out.tmp" <<'PY'
import sys, zipfile, pathlib
wheel, out = sys.argv[1], pathlib.Path(sys.argv[2])
wanted = ["unity.c", "unity.h", "unity_internals.h", "UNITY_LICENSE"]
with zipfile.ZipFile(wheel) as zf:
    for name in wanted:
        (out / name).write_bytes(zf.read("vyperling/c/" + name))
PY
    rm -rf "$out"
    mv "$out.tmp" "$out"
    say "Unity sources in $out"
}

case "${1:-all}" in
    apt) step_apt ;;
    venv) step_venv ;;
    unity) step_unity ;;
    all) step_apt; step_venv; step_unity ;;
    *) die "usage: $0 [apt|venv|unity|all]" ;;
esac
