# `make effects-demo`: SITL flights with each effect a filter term models (com_offset,
# rotor_drag, rotor_inertia, esc_delay), the term off and on, Oracle and Filter mode
# -> build/results/effects_demo.json and the table on stdout (docs/math.md §13).

.PHONY: effects-demo

EFFECTS_DEMO_ARGS ?=

effects-demo: setup host
	@cd $(REPO) && PROPID_BUILD_DIR=$(BUILD_HOST) nice -n 10 $(VENV)/bin/propid effects-demo \
	    --out $(BUILD)/results $(EFFECTS_DEMO_ARGS)
