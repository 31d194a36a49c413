# One-command entry points for a fresh machine with Python 3.11 and make.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
TEAM ?= configs/square4.yaml
OUT ?= runs/demo

.PHONY: install test demo sim bench bench-long lint clean

$(BIN)/activate: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	@echo "pip: installing the project and its test dependencies (one line per package)"
	$(BIN)/python -m pip install --progress-bar on -e '.[test]'
	$(BIN)/gcs compile
	touch $(BIN)/activate

install: $(BIN)/activate

# Three workers on two cores: the integration tests fly in real time and mostly wait (the suite
# keeps the cores ~65 % busy), so a third file in flight cuts the wall time by a quarter. Tests
# marked `alone` then run by themselves: flights whose figures the suite's own load would move
# (pyproject.toml, the marker's text). Both stages always run; the target fails at the end if
# either did. The parallel stage lists its 20 slowest tests: where the suite's time goes.
test: install
	$(BIN)/ruff check flightkit gcs vehicle_emulator tests benchmarks
	status=0; \
	$(BIN)/python -m pytest -n 3 --dist loadfile -m "not alone" --durations=20 || status=$$?; \
	$(BIN)/python -m pytest -m alone || status=$$?; \
	if [ $$status -ne 0 ]; then echo "make test: a stage failed (see above)"; fi; \
	exit $$status

# The main job: start the emulator fleet, fly the team over MAVLink, stop the emulators.
demo: install
	$(BIN)/gcs fly --team $(TEAM) --out $(OUT) --emulators

# The paper's scenarios in-process (no MAVLink).
sim: install
	$(BIN)/gcs sim --team $(TEAM) --out runs/sim

# Every benchmark whose figures docs/benchmarks.md quotes and that finishes in a few minutes
# (about 18 min in all on 2 cores), each rewriting its section of the doc as quoted there.
# bench_load and bench_actuators_busy run one busy loop per core beside the flights.
bench: install
	$(BIN)/python -m benchmarks.bench_sim --write docs/benchmarks.md
	$(BIN)/python -m benchmarks.bench_sweep
	$(BIN)/python -m benchmarks.bench_startup
	$(BIN)/python -m benchmarks.bench_edges --before ab87930 --seconds 5 --write docs/benchmarks.md
	$(BIN)/python -m benchmarks.bench_emulator --vehicles 100 --separate 4 --duration 30
	$(BIN)/python -m benchmarks.bench_fly
	$(BIN)/python -m benchmarks.bench_position_baseline
	$(BIN)/python -m benchmarks.bench_load
	$(BIN)/python -m benchmarks.bench_actuators_busy

# The long ones, each writing its section: the scale sweep to 240 vehicles (~20 min), the link
# impairment grid (48 flights, ~1 h), Scenario I from the ground twice on the shipped teams
# (~13 min; its SIH team needs the recordings).
bench-long: install
	$(BIN)/python -m benchmarks.bench_scale
	$(BIN)/python -m benchmarks.bench_links
	$(BIN)/python -m benchmarks.bench_from_ground --team px4 --team ardupilot --team mixed

lint: install
	$(BIN)/ruff check flightkit gcs vehicle_emulator tests benchmarks

clean:
	rm -rf $(VENV) runs .pytest_cache
