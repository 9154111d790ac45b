# `make gap-bench`: blind benchmark of `propid gap` (docs/gap-bench.md).
# Included by the top Makefile; uses its setup/host verbs, BUILD, BUILD_HOST and VENV.
# Flies ~85 short SITL flights with known effects on two workers, runs `propid gap`
# and the least-squares baseline on each, prints the table and writes
# build/results/gap_bench.json. A few minutes on two cores; runs under `nice`.
#
# Overrides:  make gap-bench GAP_BENCH_ARGS="--seed 2"
#             make gap-bench GAP_BENCH_ARGS="--no-tool"     (baseline only)

.PHONY: gap-bench

GAP_BENCH_OUT    ?= $(BUILD)/gap-bench
GAP_BENCH_RESULT ?= $(BUILD)/results/gap_bench.json
GAP_BENCH_ARGS   ?=

gap-bench: setup host
	@cd $(REPO) && PROPID_BUILD_DIR=$(BUILD_HOST) OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 \
	    nice -n 10 $(VENV)/bin/propid gap-bench \
	    --out $(GAP_BENCH_OUT) --result $(GAP_BENCH_RESULT) --workers $(JOBS) $(GAP_BENCH_ARGS)
