# One-command entry points for a fresh machine with Python 3.11 and make.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
TEAM ?= configs/square4.yaml
OUT ?= runs/demo

.PHONY: install test demo bench lint clean

$(BIN)/activate: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(BIN)/activate

install: $(BIN)/activate

test: install
	$(BIN)/python -m pytest

demo: install
	$(BIN)/gcs sim --team $(TEAM) --out $(OUT)

bench: install
	$(BIN)/python benchmarks/bench_sim.py

lint: install
	$(BIN)/ruff check gcs vehicle_emulator tests benchmarks

clean:
	rm -rf $(VENV) runs .pytest_cache
