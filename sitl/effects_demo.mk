# `make effects-demo`: SITL flights with each effect a filter term models (com_offset,
# rotor_drag, rotor_inertia, esc_delay), the term off and on, Oracle and Filter mode
# -> build/results/effects_demo.json and the table on stdout (docs/math.md §13).

.PHONY: effects-demo

EFFECTS_DEMO_ARGS ?=

effects-demo: setup host
	@cd $(REPO) && PROPID_BUILD_DIR=$(BUILD_HOST) nice -n 10 $(VENV)/bin/propid effects-demo \
	    --out $(BUILD)/results $(EFFECTS_DEMO_ARGS)

# `make real-data`: every mode of the optional terms on the 17 real Crazyflie logs
# (../shared, not in the repository: skipped cleanly without it) -> build/results/real_data.json
# and the tables of docs/real-data.md. 3.72e-8 is the data's independent (thrust-stand /
# accelerometer) kf from its README: it divides the results for display, no rule uses it.
.PHONY: real-data

REAL_DATA_DIR   ?= $(REPO)/../shared/data/real/crazyflie21b
REAL_DATA_REF   ?= 3.72e-8
REAL_DATA_ARGS  ?=

real-data: setup host
	@cd $(REPO) && PROPID_BUILD_DIR=$(BUILD_HOST) nice -n 10 $(VENV)/bin/propid real-data --skip-missing \
	    --data $(REAL_DATA_DIR) --reference-kf $(REAL_DATA_REF) --out $(BUILD)/results $(REAL_DATA_ARGS)
