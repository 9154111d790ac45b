# propid — every verb a developer or CI needs. `make` alone lists them.
#
# Set-up is driven from here (stamp files keep repeated calls fast):
#   Debian packages -> .venv with pinned requirements -> Unity sources.
# See docs/build.md.

SHELL := /bin/bash
.DEFAULT_GOAL := help

REPO        := $(abspath $(dir $(lastword $(MAKEFILE_LIST))))
PYTHON      ?= python3
VENV        := $(REPO)/.venv
VENV_PYTHON := $(VENV)/bin/python
BUILD       := $(REPO)/build
BUILD_HOST  := $(BUILD)/host
BUILD_TARGET:= $(BUILD)/target
BUILD_DEBUG := $(BUILD)/debug
BUILD_ASAN  := $(BUILD)/asan
DEPS        := $(BUILD)/_deps
UNITY_DIR   := $(DEPS)/unity
JOBS        ?= 2
TOOLCHAIN   := $(REPO)/firmware/toolchain/arm-none-eabi-cortex-m4f.cmake
BOOTSTRAP   := $(REPO)/host_tools/setup/bootstrap.sh

APT_STAMP   := $(DEPS)/.apt.stamp
VENV_STAMP  := $(VENV)/.propid-setup.stamp
UNITY_STAMP := $(UNITY_DIR)/.stamp

CMAKE_COMMON := -DPROPID_PYTHON=$(VENV_PYTHON) -DPROPID_UNITY_DIR=$(UNITY_DIR)

export PYTHON
MAKEFLAGS += --no-print-directory

.PHONY: help setup host target test debug asan clean test-host test-target test-python bench \
        configure-host configure-target fuzz test-fuzz cppcheck soak

help:
	@echo "propid make verbs"
	@echo "  make sitl     set up, build, fly the default closed-loop Lissajous with the filter in"
	@echo "                the loop; writes a log and a plot under build/sitl"
	@echo "  make test     set up, build host + target, run every test: Unity and SITL tests on"
	@echo "                the host, Unity tests on Cortex-M4F under QEMU, forbidden-symbol check,"
	@echo "                pytest of host_tools, every host C test again under ASan + UBSan,"
	@echo "                a short fuzz run, cppcheck"
	@echo "  make setup    Debian packages (when missing, as root), .venv with pinned requirements"
	@echo "                + host_tools, Unity sources (hash checked)"
	@echo "  make host     configure and build build/host (Release)"
	@echo "  make target   cross-build build/target for Cortex-M4F; print flash/RAM, filter size,"
	@echo "                worst stack frame"
	@echo "  make table1   run the Table 1 campaign (see docs/results.md)"
	@echo "  make gap-bench  blind benchmark of propid gap on SITL flights with known effects,"
	@echo "                next to a least-squares baseline (see docs/gap-bench.md)"
	@echo "  make xsim     propid gap and propid replay on RotorPy flights, scored against the"
	@echo "                expectations of docs/xsim.md; writes build/results/xsim.json"
	@echo "  make bench    benchmark (not a test): Cortex-M4 instructions per filter step (QEMU),"
	@echo "                dense baseline, flash/RAM/stack, SITL speed vs RotorPy, make table1 time;"
	@echo "                prints a table, writes build/results/bench.json (docs/performance.md)"
	@echo "  make table1-extended  Table 1 per preset: quads, hexa, octo (docs/results.md)"
	@echo "  make damage-bench     randomized propeller-damage flights, detector in the loop (docs/damage.md)"
	@echo "  make effects-demo     SITL effects with the filter's matching term off and on (docs/math.md §13)"
	@echo "  make real-data        the optional terms on the 17 real Crazyflie logs in ../shared (skipped without"
	@echo "                        them): build/results/real_data.json + tables (docs/real-data.md)"
	@echo "  make debug    Debug host build in build/debug + host tests"
	@echo "  make asan     AddressSanitizer + UBSan host build in build/asan + every host C test"
	@echo "                (a stage of make test)"
	@echo "  make fuzz     libFuzzer (ASan + UBSan) on the firmware API, FUZZ_RUNS=10000000"
	@echo "                executions over JOBS processes; writes build/results/fuzz.json"
	@echo "  make cppcheck static analysis of firmware/ (fails on any finding)"
	@echo "  make soak     randomized SITL flights (faults, effects, rotor losses) with the filter"
	@echo "                and the oracle in the loop, SOAK_STEPS=10000000 filter steps over JOBS"
	@echo "                processes; writes build/results/soak.json (docs/reliability.md)"
	@echo "  make clean    remove build/ (keeps .venv; rm -rf .venv to redo the venv)"
	@echo "Then: source .venv/bin/activate; propid --help"

# ---------------------------------------------------------------------------
# Set-up
# ---------------------------------------------------------------------------
setup: $(APT_STAMP) $(VENV_STAMP) $(UNITY_STAMP)

$(APT_STAMP): $(BOOTSTRAP)
	@$(BOOTSTRAP) apt
	@mkdir -p $(@D) && touch $@

$(VENV_STAMP): $(APT_STAMP) host_tools/setup/requirements.txt host_tools/pyproject.toml $(BOOTSTRAP)
	@$(BOOTSTRAP) venv
	@touch $@

$(UNITY_STAMP): $(APT_STAMP) $(BOOTSTRAP)
	@$(BOOTSTRAP) unity
	@touch $@

# ---------------------------------------------------------------------------
# Builds
# ---------------------------------------------------------------------------
configure-host: setup
	@cmake -S $(REPO) -B $(BUILD_HOST) -DCMAKE_BUILD_TYPE=Release $(CMAKE_COMMON) >/dev/null

host: configure-host
	@cmake --build $(BUILD_HOST) -j$(JOBS)

configure-target: setup
	@cmake -S $(REPO) -B $(BUILD_TARGET) -DCMAKE_BUILD_TYPE=Release \
	    -DCMAKE_TOOLCHAIN_FILE=$(TOOLCHAIN) $(CMAKE_COMMON) >/dev/null

target: configure-target
	@cmake --build $(BUILD_TARGET) -j$(JOBS)
	@bash $(REPO)/firmware/toolchain/footprint.sh $(BUILD_TARGET)

debug: setup
	@cmake -S $(REPO) -B $(BUILD_DEBUG) -DCMAKE_BUILD_TYPE=Debug $(CMAKE_COMMON) >/dev/null
	@cmake --build $(BUILD_DEBUG) -j$(JOBS)
	@cd $(BUILD_DEBUG) && ctest -j$(JOBS) --output-on-failure

asan: setup
	@cmake -S $(REPO) -B $(BUILD_ASAN) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPROPID_SANITIZE=ON \
	    $(CMAKE_COMMON) >/dev/null
	@cmake --build $(BUILD_ASAN) -j$(JOBS)
	@cd $(BUILD_ASAN) && ASAN_OPTIONS=detect_leaks=1:abort_on_error=0 \
	    UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 ctest -j$(JOBS) --output-on-failure

# ---------------------------------------------------------------------------
# Tests: every stage runs even when an earlier one failed, so one run shows
# all failures; the verb fails if any stage failed.
# ---------------------------------------------------------------------------
test-host: configure-host
	@cmake --build $(BUILD_HOST) -j$(JOBS)
	@cd $(BUILD_HOST) && ctest -j$(JOBS) --output-on-failure

test-target: configure-target
	@cmake --build $(BUILD_TARGET) -j$(JOBS)
	@cd $(BUILD_TARGET) && ctest -j$(JOBS) --output-on-failure

# pytest exit 5 = "no tests collected": acceptable only when there is no test file.
test-python: setup
	@cd $(REPO) && status=0; \
	PROPID_BUILD_DIR=$(BUILD_HOST) $(VENV_PYTHON) -m pytest -q tests/host_tools || status=$$?; \
	if [ $$status -eq 5 ] && ! compgen -G "tests/host_tools/test_*.py" >/dev/null \
	        && ! compgen -G "tests/host_tools/*_test.py" >/dev/null; then \
	    echo "pytest: no Python test files in tests/host_tools"; status=0; \
	fi; exit $$status

# Each stage's output is also kept in build/test-logs/ so the closing line can
# add up the ctest and pytest counts into one "N passed, N failed".
test: setup
	@start=$$(date +%s); failed=""; logs=$(BUILD)/test-logs; rm -rf $$logs; mkdir -p $$logs; \
	stage() { local name=$$1; shift; local t0=$$(date +%s); \
	    echo; echo "=== make test: $$name"; \
	    if set -o pipefail && "$$@" 2>&1 | tee $$logs/$$name.log; then echo "=== $$name: ok ($$(( $$(date +%s) - t0 )) s)"; \
	    else echo "=== $$name: FAILED ($$(( $$(date +%s) - t0 )) s)"; failed="$$failed $$name"; fi; }; \
	stage host-build    $(MAKE) --no-print-directory host; \
	stage host-tests    $(MAKE) --no-print-directory test-host; \
	stage target-build  $(MAKE) --no-print-directory target; \
	stage target-tests  $(MAKE) --no-print-directory test-target; \
	stage python-tests  $(MAKE) --no-print-directory test-python; \
	stage sanitizers    $(MAKE) --no-print-directory asan; \
	stage fuzz-short    $(MAKE) --no-print-directory test-fuzz; \
	stage cppcheck      $(MAKE) --no-print-directory cppcheck; \
	echo; echo "=== make test: $$(( $$(date +%s) - start )) s"; \
	if [ -n "$$failed" ]; then echo "=== FAILED:$$failed"; fi; \
	$(PYTHON) $(REPO)/tests/count_results.py $$logs $$failed; \
	if [ -n "$$failed" ]; then exit 1; fi

# Benchmark, not a test (docs/performance.md). BENCH_SKIP=rotorpy,table1 leaves parts out.
BENCH_SKIP ?=
bench: setup host target
	@cd $(REPO) && $(VENV_PYTHON) tests/bench/bench.py --repo $(REPO) --build $(BUILD) \
	    $(if $(BENCH_SKIP),--skip $(BENCH_SKIP))

clean:
	rm -rf $(BUILD)

# ---------------------------------------------------------------------------
# Reliability (docs/reliability.md): fuzzing and static analysis.
# ---------------------------------------------------------------------------
FUZZ_RUNS ?= 10000000
FUZZ_RUNS_SHORT ?= 100000

fuzz: setup
	@bash $(REPO)/tests/fuzz/run_fuzz.sh --runs $(FUZZ_RUNS) --jobs $(JOBS)

# The short run inside `make test`: the committed seed corpus plus a fixed number of
# executions from a fixed seed (about 20-40 s), so the same tree gives the same verdict.
# Any covariance check that finds P not positive definite fails it (the seed corpus
# holds the inputs that once did).
test-fuzz: setup
	@bash $(REPO)/tests/fuzz/run_fuzz.sh --runs $(FUZZ_RUNS_SHORT) --jobs 1 --fail-on-indefinite \
	    --out $(BUILD)/fuzz-short --json $(BUILD)/results/fuzz-short.json

# Not a test: a measurement over SOAK_STEPS filter steps (about 3 min at 10^7 on
# 2 idle cores); fails only on a NaN estimate or a flight that could not run.
SOAK_STEPS ?= 10000000
SOAK_SEED ?= 1
SOAK_NEES_TUNING ?= matched
SOAK_INERTIA_STD ?=
SOAK_GYRO_STUCK ?= 0
SOAK_NEES_RATE_RULE ?= none
SOAK_NEES_DEFAULT_RATE_NOISE ?=
soak: setup host
	@cd $(REPO) && nice -n 10 $(VENV_PYTHON) tests/soak/soak.py --sitl $(BUILD_HOST)/sitl/propid_sitl \
	    --steps $(SOAK_STEPS) --seed $(SOAK_SEED) --jobs $(JOBS) --nees-tuning $(SOAK_NEES_TUNING) \
	    --nees-rate-rule $(SOAK_NEES_RATE_RULE) \
	    $(if $(SOAK_NEES_DEFAULT_RATE_NOISE),--nees-default-rate-noise $(SOAK_NEES_DEFAULT_RATE_NOISE)) \
	    $(if $(SOAK_INERTIA_STD),--inertia-std $(SOAK_INERTIA_STD)) --gyro-stuck $(SOAK_GYRO_STUCK) \
	    --out $(BUILD)/results/soak.json

cppcheck: setup
	@cppcheck --error-exitcode=1 --enable=warning,style,performance,portability --std=c11 \
	    --inline-suppr -q -I $(REPO)/firmware/include $(REPO)/firmware/src $(REPO)/firmware/port \
	    && echo "cppcheck: firmware/ clean"

# Simulator verbs: `sitl` and `table1`. They may use BUILD_HOST, VENV_PYTHON
# and the `host` / `setup` verbs above.
include $(REPO)/sitl/sitl.mk
include $(REPO)/sitl/table1.mk
include $(REPO)/host_tools/gap_bench.mk
include $(REPO)/tests/xsim/xsim.mk
include $(REPO)/sitl/damage_bench.mk
include $(REPO)/sitl/table1_extended.mk
include $(REPO)/sitl/effects_demo.mk
