# The two commands a newcomer runs: `make run` (simulated MARTE) and `make test`.
# Both create .venv from pyproject.toml on first use.
# The interpreter .venv is made from: the system's Python 3 (/usr/bin/python3) when it is 3.11+
# and can make a venv and compile extensions, else the first python3 on PATH. Debian builds its
# Python with profile-guided and link-time optimization; a default pyenv build of the same
# version ran a simulated mission 13 % slower, with the same results (docs/developing/
# benchmarks-mission.md). `make PYTHON=python3.12 ...` chooses another.
SYSTEM_PYTHON := $(shell /usr/bin/python3 scripts/pick_python.py 2>/dev/null)
PYTHON ?= $(or $(SYSTEM_PYTHON),python3)
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
BUILD_ACCEL = $(PY) scripts/build_accel.py || echo "make: the compiled hot path did not build;" \
	"RAMP runs the sources (the same results, slower)"

.PHONY: run teleop mission fleet campaign screenshots test lint bench bench-quick fuzz soak soak-safety clean docs accel test-deployed

# RAMP, then the example plugins: Scout's arm, and the guides' winch (SPEC 10: installed as a
# team installs a plugin package; their entry points are what RAMP finds).
$(STAMP): pyproject.toml examples/ramp-arm/pyproject.toml examples/ramp-winch/pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	$(PY) -m pip install --quiet -e examples/ramp-arm
	$(PY) -m pip install --quiet -e examples/ramp-winch
	$(BUILD_ACCEL)
	touch $(STAMP)

# The simulator's hot path (the physics, the emulators, the AHRS; nothing of the backend)
# compiled with mypyc into build/accel/ (scripts/build_accel.py, ramp/common/accel.py) at
# install: a simulated mission runs faster, with the same results. `make accel` (and the
# targets that run missions) rebuild it when one of its sources, or a module they import,
# changed; until then, and wherever it cannot be built (no C compiler), RAMP runs the sources.
ACCEL := build/accel/manifest.json
ACCEL_SOURCES := $(shell $(PYTHON) scripts/build_accel.py --list)
$(ACCEL): scripts/build_accel.py $(ACCEL_SOURCES) | $(STAMP)
	$(BUILD_ACCEL)

accel: $(ACCEL)

run: $(STAMP)
	$(VENV)/bin/ramp run --sim --config ramp.yaml --host 127.0.0.1

# A first look at the operator console: simulated MARTE and ramp-teleop together; Ctrl-C
# stops both. Open the address it prints (http://127.0.0.1:8080/).
ROBOT_PORT ?= 5577
TELEOP_PORT ?= 8080
teleop: $(STAMP)
	@$(VENV)/bin/ramp run --sim --config ramp.yaml --host 127.0.0.1 --port $(ROBOT_PORT) & \
	robot=$$!; trap 'kill $$robot 2>/dev/null; wait $$robot 2>/dev/null' EXIT; \
	$(VENV)/bin/ramp-teleop --backend 127.0.0.1:$(ROBOT_PORT) --http-port $(TELEOP_PORT)

# A whole RMC mission on the wall clock, its live view, and the operator console wired to
# both (SPEC 7.1): open the address it prints to watch the mission's state, map and alerts,
# and take over from an alert; Ctrl-C stops both. The view also opens in Foxglove
# (ws://127.0.0.1:$(VIEW_PORT)).
VIEW_PORT ?= 8765
mission: $(STAMP) $(ACCEL)
	@$(VENV)/bin/ramp sim mission --realtime --port $(ROBOT_PORT) --foxglove-port $(VIEW_PORT) & \
	robot=$$!; trap 'kill $$robot 2>/dev/null; wait $$robot 2>/dev/null' EXIT; \
	sleep 2; $(VENV)/bin/ramp-teleop --backend 127.0.0.1:$(ROBOT_PORT) \
	  --autonomy 127.0.0.1:$(VIEW_PORT) --http-port $(TELEOP_PORT)

# A fleet on this machine (SPEC 14): a local Mosquitto, MARTE with the autonomy, MARTE without,
# Scout, each with its fleet agent, and the supervisor's page; open the address it prints.
# Ctrl-C stops the robots first, then the rest.
FLEET_PORT ?= 8090
fleet: $(STAMP)
	$(VENV)/bin/ramp fleet sim --http-port $(FLEET_PORT) --consoles

# The issue's campaign: 40 seeded missions over both start boxes and all four headings.
campaign: $(STAMP) $(ACCEL)
	$(VENV)/bin/ramp sim campaign --runs 40

lint: $(STAMP)
	$(VENV)/bin/ruff check ramp firmware_like tests bench examples
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports

test: lint $(ACCEL)
	$(PY) -m pytest
	$(MAKE) --no-print-directory test-deployed

# The backend's safety suites (watchdog, arbitration, interlocks, stalls, drivers) once more
# as the robot runs them: RAMP_ACCEL=0, every module from its sources, as the service install
# (no build) runs it. `make test` ran them beside the compiled simulator; the backend itself
# is never compiled (scripts/build_accel.py), so both runs test the code the robot runs.
SAFETY_SUITES := tests/hil_sim/test_safety.py tests/hil_sim/test_safety_model.py \
	tests/hil_sim/test_latched_faults.py tests/hil_sim/test_latch_restart.py \
	tests/hil_sim/test_commanders.py \
	tests/hil_sim/test_interlocks.py tests/hil_sim/test_scout_interlocks.py \
	tests/hil_sim/test_stalls.py tests/hil_sim/test_driver_bugs.py \
	tests/hil_sim/test_plugin_bugs.py \
	tests/hil_sim/test_room_for_a_stop.py tests/unit/test_scheduler.py \
	tests/unit/test_sabertooth_driver.py tests/unit/test_odrive_driver.py \
	tests/unit/test_phidget_driver.py
test-deployed: $(STAMP)
	RAMP_ACCEL=0 $(PY) -m pytest -q $(SAFETY_SUITES)

bench: $(STAMP) $(ACCEL)
	$(PY) -m bench

bench-quick: $(STAMP) $(ACCEL)
	$(PY) -m bench --quick

fuzz: $(STAMP)
	RAMP_FUZZ_EXAMPLES=20000 $(PY) -m pytest tests/fuzz -q

# The model-based test of SPEC 2.2 (watchdog, latched faults) at length: `make test` runs 12.
soak-safety: $(STAMP)
	RAMP_SAFETY_EXAMPLES=400 $(PY) -m pytest tests/hil_sim/test_safety_model.py -q

clean:
	rm -rf $(VENV) build .pytest_cache .mypy_cache .ruff_cache .hypothesis .import_linter_cache site

# The documentation site (docs/, mkdocs.yml) into site/; open site/index.html. --strict: a
# broken link, anchor or API page fails it. tests/unit/test_docs.py builds it in `make test`.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

# Refresh the console's screenshots: the browser tests take them (docs/img/teleop.png,
# docs/img/console-autonomy.png, and docs/img/console-scout.png of Scout).
screenshots: $(STAMP)
	RAMP_UPDATE_DOCS=1 $(PY) -m pytest -q tests/hil_sim/test_teleop_browser.py \
	  tests/hil_sim/test_console_autonomy_browser.py tests/hil_sim/test_scout_console.py
