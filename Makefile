# Two entry points for a fresh clone: `make run` (main job) and `make test`.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test lint bench clean

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $(STAMP)

run: $(STAMP)
	rm -rf results/compare
	@echo "make run compares the paper's dial-gauge procedure and a laser tracker (agents), each read by \
	the paper's 6-parameter model and by the model of all 27 machine errors (estimators), \
	on the same 200 random machines:"
	$(BIN)/orthoglide compare --agents paper,tracker --estimators paper6,extended \
		--machines 200 --seed 1 --jobs 2 --out results/compare

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q -n auto

bench: $(STAMP)
	$(BIN)/python benchmarks/fidelity.py --machines 200
	$(BIN)/python benchmarks/bench_machine.py
	$(BIN)/python benchmarks/bench_env.py
	$(BIN)/python benchmarks/bench_vector.py
	$(BIN)/python benchmarks/bench_lab_vector.py
	$(BIN)/python benchmarks/bench_build.py
	$(BIN)/python benchmarks/statistics.py
	$(BIN)/python benchmarks/realistic.py
	$(BIN)/python benchmarks/bench_calibrators.py
	$(BIN)/python benchmarks/bench_compare.py
	$(BIN)/python benchmarks/bench_active.py
	$(BIN)/python benchmarks/bench_measurements.py
	$(BIN)/python benchmarks/bench_fit.py
	$(BIN)/python benchmarks/estimators.py
	$(BIN)/python benchmarks/speed_against_revision.py --rev 02c124b

clean:
	rm -rf $(VENV) results .pytest_cache
