# `make table1-extended`: the Table 1 campaign per vehicle preset (docs/results.md):
# crazyflie-plus/-x in the three modes, hexa/octo plus/X in Filter and Oracle,
# EXTENDED_TRIALS flights per cell on two workers -> build/results/table1_extended.json.

.PHONY: table1-extended

EXTENDED_OUT    ?= $(BUILD)/results
EXTENDED_TRIALS ?= 30
EXTENDED_ARGS   ?=

table1-extended: setup host
	@cd $(REPO) && PROPID_BUILD_DIR=$(BUILD_HOST) nice -n 10 $(VENV)/bin/propid table1-extended \
	    --out $(EXTENDED_OUT) --trials $(EXTENDED_TRIALS) $(EXTENDED_ARGS)
