# `make damage-bench`: randomized propeller-damage flights with the firmware's
# damage detector in the loop (docs/damage.md): DAMAGE_DAMAGED damaged flights
# (each also flown in Oracle mode) + DAMAGE_UNDAMAGED undamaged ones with effects,
# on two workers -> build/results/damage_bench.json and the table on stdout.

.PHONY: damage-bench

DAMAGE_OUT       ?= $(BUILD)/results
DAMAGE_DAMAGED   ?= 200
DAMAGE_UNDAMAGED ?= 100
DAMAGE_ARGS      ?=

damage-bench: setup host
	@cd $(REPO) && PROPID_BUILD_DIR=$(BUILD_HOST) nice -n 10 $(VENV)/bin/propid damage-bench \
	    --out $(DAMAGE_OUT) --damaged $(DAMAGE_DAMAGED) --undamaged $(DAMAGE_UNDAMAGED) $(DAMAGE_ARGS)
