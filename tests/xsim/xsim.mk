# `make xsim`: `propid gap` and `propid replay` on RotorPy flights (docs/xsim.md).
# Included by the top Makefile; uses its setup/host verbs, BUILD, BUILD_HOST and VENV.
# A cross-simulator check, not a test: RotorPy (pinned, in the bench-only venv of
# `make bench`) flies 7 short flights, the tools run on each, every answer is scored
# against the expectations in docs/xsim.md; prints the table and writes
# build/results/xsim.json. About 5 minutes on one core; runs under `nice`.
#
# Overrides:  make xsim XSIM_ARGS="--flights cf-liss-off,hb-liss-on --duration 30"

.PHONY: xsim

XSIM_ARGS ?=

xsim: setup host
	@cd $(REPO) && PROPID_BUILD_DIR=$(BUILD_HOST) OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 \
	    nice -n 10 $(VENV_PYTHON) tests/xsim/xsim.py --repo $(REPO) --build $(BUILD) $(XSIM_ARGS)
