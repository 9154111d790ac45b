# `make table1`: the paper's Table 1 experiment (docs/results.md).
# Included by the top Makefile; uses its setup/host verbs, BUILD_HOST and VENV.
# 3 trajectories x 3 modes x TABLE1_TRIALS seeded flights of propid_sitl on two
# workers, then build/results/table1.json and table1.md (+ table1.png).
# Takes a few minutes on two cores; runs under `nice`.

.PHONY: table1

TABLE1_OUT    ?= $(BUILD)/results
TABLE1_TRIALS ?= 10
TABLE1_ARGS   ?=

table1: setup host
	@cd $(REPO) && PROPID_BUILD_DIR=$(BUILD_HOST) nice -n 10 $(VENV)/bin/propid campaign \
	    --out $(TABLE1_OUT) --trials $(TABLE1_TRIALS) $(TABLE1_ARGS)
	@cd $(REPO) && $(VENV)/bin/propid table1 $(TABLE1_OUT)/table1.json --png $(TABLE1_OUT)/table1.png >/dev/null
	@echo "table1: $(TABLE1_OUT)/table1.md, $(TABLE1_OUT)/table1.png"
