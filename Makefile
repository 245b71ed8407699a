# gyroarray — the two commands a newcomer runs: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# sweep worker processes (one per core)
WORKERS ?= $(shell nproc 2>/dev/null || echo 2)

.PHONY: demo test fuzz bench score venv clean

venv: $(STAMP)

# (Re)install when the project's metadata changes; the install is editable,
# so code changes need no reinstall.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip setuptools wheel
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/gyroarray design
	$(VENV)/bin/gyroarray design --paper-tables
	$(VENV)/bin/gyroarray design --plot reports/demo/design_gdop.png --force
	$(VENV)/bin/gyroarray simulate scenarios/examples/tetra_swing.toml --out reports/demo --force
	$(VENV)/bin/gyroarray allan reports/demo/tetra_swing.csv.gz --plot reports/demo/tetra_swing_adev.png --force
	$(VENV)/bin/gyroarray sweep scenarios/sweeps/design_quick.toml --out reports/demo/design_quick --workers $(WORKERS)
	$(VENV)/bin/gyroarray sweep scenarios/sweeps/paper_reproduction.toml --out reports/demo/paper_reproduction --workers $(WORKERS)
	$(VENV)/bin/gyroarray report reports/demo/design_quick reports/demo/paper_reproduction --out reports/demo/report.html --md reports/demo/report.md --force
	@echo "demo: the design comparison report is reports/demo/report.html (open it in a browser; Markdown twin reports/demo/report.md)"
	@echo "demo: also wrote reports/demo/design_gdop.png, reports/demo/tetra_swing.csv.gz (+ .toml), reports/demo/tetra_swing_adev.png"

test: $(STAMP)
	$(PY) -m pytest -q -n $(WORKERS)
	$(VENV)/bin/gyroarray check

# long fuzzing of the CLI with generated hostile inputs (issue 17; make test runs 25 examples)
FUZZ_EXAMPLES ?= 2000
fuzz: $(STAMP)
	GYROARRAY_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) $(PY) -m pytest -q -n $(WORKERS) tests/test_fuzz.py tests/test_hostile.py

bench: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) benchmarks/run.py

# how often diagnose names a hidden effect right (not a speed benchmark; ~4 min)
score: $(STAMP)
	mkdir -p bench_out
	OPENBLAS_NUM_THREADS=1 $(PY) benchmarks/diagnosis_score.py --seeds 2 --json bench_out/diagnosis_score.json

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis reports/demo
