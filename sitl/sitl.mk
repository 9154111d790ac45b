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
# Variables (each replaces one flight setting; the rest stay as above):
#   make sitl VEHICLE=hummingbird-x          preset name or a vehicle JSON file
#   make sitl TRAJECTORY=circle              hover | step | circle | lissajous
#   make sitl EFFECTS=rotor_drag,esc_delay=0.01   comma list of NAME[=STRENGTH]
#   make sitl MODE=oracle SEED=3 DURATION=20
#   make sitl SENSORS=default                the BMI088/DShot models instead of --paper
#   make sitl REALTIME=0                     as fast as possible
#   make sitl SITL_FILTER=                   library-default filter tuning
#   make sitl SITL_EXTRA="--esc-dropout 0"   any other propid_sitl option, added

.PHONY: sitl

comma := ,
SITL_OUT     ?= $(BUILD)/sitl
REALTIME     ?= 1
SITL_MAVLINK ?= udp:127.0.0.1:14550
VEHICLE      ?= crazyflie-plus
TRAJECTORY   ?= lissajous
MODE         ?= filter
SEED         ?= 1
DURATION     ?= 10
EFFECTS      ?=
SENSORS      ?= paper
SITL_FLIGHT  := $(if $(filter paper,$(SENSORS)),--paper) --vehicle $(VEHICLE) \
                --trajectory $(TRAJECTORY) --mode $(MODE) --seed $(SEED) --duration $(DURATION) \
                $(foreach effect,$(subst $(comma), ,$(EFFECTS)),--effect $(effect)) \
                --start-at-rest --coeff-spread 0.2 --gyro-bias-max 0.0174533 \
                --incorrect-source nominal
# = propid campaign's Filter-mode configuration (host_tools/propid/campaign.py);
# 0.11547 = 0.2/sqrt(3), 0.0100767 = 0.0174533/sqrt(3).
SITL_FILTER  ?= --prior-kf-std 0.11547 --prior-km-std 0.11547 --prior-bias-std 0.0100767 \
                --prior-rate-std 0.01 \
                --filter-rate-noise 0.0004 --filter-coeff-walk 0.0 --filter-bias-walk 0.0
SITL_EXTRA   ?=
SITL_ALL      = $(strip $(SITL_FLIGHT) $(SITL_FILTER) $(SITL_EXTRA))

sitl: setup host
	@case "$(SENSORS)" in paper|default) ;; *) echo "sitl: SENSORS=$(SENSORS): paper or default" >&2; exit 2;; esac
	@mkdir -p $(SITL_OUT)
	@echo "sitl: flying ($(SITL_ALL)), realtime $(REALTIME), MAVLink $(SITL_MAVLINK)"
	@status=0; $(BUILD_HOST)/sitl/propid_sitl $(SITL_ALL) --realtime $(REALTIME) \
	    --log $(SITL_OUT)/flight.csv --summary-json $(SITL_OUT)/summary.json \
	    $(if $(SITL_MAVLINK),--mavlink $(SITL_MAVLINK)) || status=$$?; \
	if [ $$status -ne 0 ] && [ $$status -ne 3 ]; then exit $$status; fi; \
	cd $(REPO) && $(VENV)/bin/propid plot --log $(SITL_OUT)/flight.csv --summary $(SITL_OUT)/summary.json \
	    --out $(SITL_OUT)/estimates.png \
	    || exit $$?; \
	echo "sitl: log      $(SITL_OUT)/flight.csv (+ flight.vehicle.json)"; \
	echo "sitl: summary  $(SITL_OUT)/summary.json"; \
	echo "sitl: plot     $(SITL_OUT)/estimates.png"; \
	exit $$status
