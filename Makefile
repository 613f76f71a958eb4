# Two entry points for a fresh clone: `make run` (main job) and `make test`.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test docs lint bench clean

# Python writes a module's bytecode as it first imports it, also where the environment
# says not to (container images): every worker and every command a test starts would
# compile its imports again.  So the suite and the commands compile the part of the venv
# they import, not pip (one file at a time) nor compileall (all 6222 files, 21 CPU-s).
unexport PYTHONDONTWRITEBYTECODE

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet --no-compile -e '.[dev,pdf]'
	touch $(STAMP)

run: $(STAMP)
	@echo "make run: the paper's dial-gauge procedure, a designed gauge experiment (optimal) and a \
	laser tracker (agents), each read by the full model of the machine's errors and the lab's terms \
	(estimator), on the same 10 realistic machines in the real lab (--conditions lab), one hour \
	of lab time at most:"
	$(BIN)/orthoglide compare --agents paper,optimal,tracker --estimators full \
		--machines 10 --seed 1 --conditions lab --jobs 2
	@echo
	@echo "Next: docs/getting-started.md; an RL researcher docs/env.md, a calibration researcher \
	docs/compare.md and docs/benchmarks.md, a machine builder docs/workflow.md (make docs builds \
	the site into docs/_build/html)."

# The package compiled first, once: the workers would otherwise both compile it as they
# collect.
# NUMPY_MADVISE_HUGEPAGE=0: each 2 MB page numpy asks of the kernel for a large array costs
# milliseconds to zero on a virtual machine, and the suite's arrays are short-lived.
# OPENBLAS_NUM_THREADS=1: the workers already fill the cores; BLAS threads of their own
# would only contend for them.
# --dist worksteal: a worker that runs out takes half of another's queue. The default
# opens each worker with a block of a quarter of its share, so the first held every slow
# test and ran them all while the other, the rest done, idled (5.7 minutes of a loaded run).
test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m compileall -q orthoglide_env calibrators
	NUMPY_MADVISE_HUGEPAGE=0 OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -q -n auto \
		--dist worksteal

docs: $(STAMP)
	$(BIN)/python -m sphinx -W --keep-going -b html docs docs/_build/html

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
	rm -rf $(VENV) results .pytest_cache docs/_build
