# One-command entry points for a fresh machine with Python 3.11 and make.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
TEAM ?= configs/square4.yaml
OUT ?= runs/demo

.PHONY: install test demo sim bench lint clean

$(BIN)/activate: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	$(BIN)/gcs compile
	touch $(BIN)/activate

install: $(BIN)/activate

# Three workers on two cores: the integration tests fly in real time and mostly wait (the suite
# keeps the cores ~65 % busy), so a third file in flight cuts the wall time by a quarter. Tests
# marked `alone` then run by themselves: flights whose figures the suite's own load would move
# (pyproject.toml, the marker's text).
test: install
	$(BIN)/ruff check gcs vehicle_emulator tests benchmarks
	$(BIN)/python -m pytest -n 3 --dist loadfile -m "not alone"
	$(BIN)/python -m pytest -m alone

# The main job: start the emulator fleet, fly the team over MAVLink, stop the emulators.
demo: install
	$(BIN)/gcs fly --team $(TEAM) --out $(OUT) --emulators

# The paper's scenarios in-process (no MAVLink).
sim: install
	$(BIN)/gcs sim --team $(TEAM) --out runs/sim

bench: install
	$(BIN)/python benchmarks/bench_sim.py --write docs/benchmarks.md
	$(BIN)/python benchmarks/bench_emulator.py
	$(BIN)/python benchmarks/bench_fly.py

lint: install
	$(BIN)/ruff check gcs vehicle_emulator tests benchmarks

clean:
	rm -rf $(VENV) runs .pytest_cache
