# `make sitl`: fly the default closed-loop Lissajous with the filter in the
# loop (Crazyflie, plus frame, seed 1, 10 s at real time): the flight of trial 0
# of the Table 1 campaign's Lissajous/Filter cell (docs/results.md: the paper's
# sensors, start hovering at rest, and the campaign's filter configuration:
# priors = the truth distribution's std, no random walks, gyro noise = the
# simulated gyro's, rate process noise 0.0004, body-rate prior 0.01 rad/s). Streams MAVLink to
# udp:127.0.0.1:14550 (QGroundControl / `propid listen` can watch), logs the
# flight and plots the estimates against the truth (docs/sitl.md).
# Included by the top Makefile; uses its setup/host verbs, BUILD, BUILD_HOST, VENV.
#
# Overrides:  make sitl REALTIME=0                  (as fast as possible)
#             make sitl SITL_ARGS="--mode oracle"   (replaces the flight options)
#             make sitl SITL_FILTER=                (library-default filter tuning)
#             make sitl SITL_EXTRA="--effect rotor_drag"   (added to them)

.PHONY: sitl

SITL_OUT     ?= $(BUILD)/sitl
REALTIME     ?= 1
SITL_MAVLINK ?= udp:127.0.0.1:14550
SITL_ARGS    ?= --paper --vehicle crazyflie-plus --trajectory lissajous --mode filter --seed 1 \
                --duration 10 --start-at-rest --coeff-spread 0.2 --gyro-bias-max 0.0174533 \
                --incorrect-source nominal
# = propid campaign's Filter-mode configuration (host_tools/propid/campaign.py);
# 0.11547 = 0.2/sqrt(3), 0.0100767 = 0.0174533/sqrt(3).
SITL_FILTER  ?= --prior-kf-std 0.11547 --prior-km-std 0.11547 --prior-bias-std 0.0100767 \
                --prior-rate-std 0.01 \
                --filter-rate-noise 0.0004 --filter-coeff-walk 0.0 --filter-bias-walk 0.0
SITL_EXTRA   ?=

sitl: setup host
	@mkdir -p $(SITL_OUT)
	@echo "sitl: flying ($(SITL_ARGS) $(SITL_FILTER) $(SITL_EXTRA)), realtime $(REALTIME), MAVLink $(SITL_MAVLINK)"
	@status=0; $(BUILD_HOST)/sitl/propid_sitl $(SITL_ARGS) $(SITL_FILTER) $(SITL_EXTRA) --realtime $(REALTIME) \
	    --log $(SITL_OUT)/flight.csv --summary-json $(SITL_OUT)/summary.json \
	    $(if $(SITL_MAVLINK),--mavlink $(SITL_MAVLINK)) || status=$$?; \
	if [ $$status -ne 0 ] && [ $$status -ne 3 ]; then exit $$status; fi; \
	cd $(REPO) && $(VENV)/bin/propid plot --log $(SITL_OUT)/flight.csv --out $(SITL_OUT)/estimates.png \
	    || exit $$?; \
	echo "sitl: log      $(SITL_OUT)/flight.csv (+ flight.vehicle.json)"; \
	echo "sitl: summary  $(SITL_OUT)/summary.json"; \
	echo "sitl: plot     $(SITL_OUT)/estimates.png"; \
	exit $$status
