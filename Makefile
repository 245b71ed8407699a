# gyroarray — the two commands a newcomer runs: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# sweep worker processes (one per core)
WORKERS ?= $(shell nproc 2>/dev/null || echo 2)

.PHONY: demo paper test lint docs docs-numbers fuzz bench score typecheck venv clean

venv: $(STAMP)

# (Re)install when the project's metadata changes; the install is editable,
# so code changes need no reinstall.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip setuptools wheel
	$(PY) -m pip install --quiet -e '.[test,docs]'
	touch $(STAMP)

# The design question of the demo: paper 003's simulated gyros (ARW 0.1 deg/rt(h), RRW
# 600 deg/h/rt(h), 100 Hz), a 5 deg/s swing at 0.03 Hz about each axis, 10 min, N = 4..8,
# one failure to survive, the gyros' correlation anywhere in [-0.1, 0.5].
DEMO_ARGS = --arw 0.1 --rrw 600 --rate-hz 100 --horizon-s 600 --swing 5,0.03 --n 4,5,6,8 \
            --failures 1 --rho-range=-0.1,0.5

# The decision from the analytic predictor, 20 paired simulated runs of the top designs beside
# it, and the report (about 30 s of compute; benchmarks/bench_design.py times it).
demo: $(STAMP)
	mkdir -p reports/demo
	$(VENV)/bin/gyroarray design --paper-tables
	$(VENV)/bin/gyroarray design --recommend $(DEMO_ARGS) --check 20 --out reports/demo/design.json --force > reports/demo/design.txt
	$(VENV)/bin/gyroarray report --design reports/demo/design.json --out reports/demo/report.html --md reports/demo/report.md --force
	@echo "demo: the design report is reports/demo/report.html (Markdown twin reports/demo/report.md); all designs: reports/demo/design.txt"
	@echo "demo: the papers' experiments beside the model: make paper (several minutes)"
	@tail -n 3 reports/demo/design.txt

# Every paper experiment 20 times (the report's 95 % bands) and its named hypothesis checks,
# added to the demo's report (several minutes on 2 cores).
paper: demo
	$(VENV)/bin/gyroarray sweep src/gyroarray/data/scenarios/sweeps/paper_reproduction.toml --out reports/demo/paper_reproduction --workers $(WORKERS)
	$(VENV)/bin/gyroarray report reports/demo/paper_reproduction --design reports/demo/design.json --out reports/demo/report.html --md reports/demo/report.md --force
	@tail -n 3 reports/demo/design.txt

# the long statistical cases (marked slow) run in make score
test: $(STAMP) lint
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q -n $(WORKERS) -m "not slow"
	$(VENV)/bin/gyroarray check

# ruff, configured in pyproject.toml ([tool.ruff]); tests/test_layers.py holds the import layers
lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks examples docs

# the documentation site: docs/*.md (MyST) and the API reference from the numpydoc docstrings,
# into build/docs/index.html (.ci/run builds it after make test; about a minute)
docs: $(STAMP)
	rm -rf docs/_api build/docs
	PYTHONWARNINGS=ignore $(PY) -m sphinx -q -b html docs build/docs
	@echo "docs: build/docs/index.html"

# the numbers the docs quote, regenerated from the runs that produce them (the passages between
# <!-- numbers:NAME --> and <!-- /numbers --> in docs/*.md; about 35 s). Add CHECK=1 to only
# report stale passages (exit 1), as a docs build step
docs-numbers: $(STAMP)
	$(PY) scripts/docs_numbers.py $(if $(CHECK),--check,)

# long fuzzing of the CLI with generated hostile inputs and arguments (issues 17, 28): FUZZ_EXAMPLES
# generated examples in all (tests/test_fuzz.py shares them out); make test runs a small fixed sample
FUZZ_EXAMPLES ?= 2000
fuzz: $(STAMP)
	GYROARRAY_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) $(PY) -m pytest -q -n $(WORKERS) tests/test_fuzz.py tests/test_fuzz_args.py tests/test_fuzz_readers.py \
		tests/test_hostile.py tests/test_hostile_files.py tests/test_hostile_fdi.py tests/test_hostile_counts.py \
		tests/test_hostile_models.py tests/test_hostile_output.py

bench: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) benchmarks/run.py
	$(if $(CONVERT_SIZES),OPENBLAS_NUM_THREADS=1 $(PY) benchmarks/bench_convert_memory.py --sizes $(CONVERT_SIZES),)

# the slow test cases (every practice-shaped effect and practice file, ~10 min), how often
# diagnose names a hidden effect right (not a speed benchmark; ~15 min), the
# analytic predictor against 30 simulated runs of every quick-sweep design (~3 min), and
# how often a pure random walk breaks the ADEV "point bound" on K (~3 min), and the 1σ
# coverage of a Gauss-Markov fit through the chain on 40 drawn cases (~5 min), and how often
# the Gauss-Markov scan calls a hump in pure ARW + RRW (~8 min); the same diagnosis score on
# records of an independent generator written from shared/spec alone (~5 min)
score: $(STAMP)
	mkdir -p bench_out
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q -n $(WORKERS) -m slow
	OPENBLAS_NUM_THREADS=1 $(PY) benchmarks/diagnosis_score.py --seeds 6 --json bench_out/diagnosis_score.json
	OPENBLAS_NUM_THREADS=1 $(PY) benchmarks/independent_score.py --seeds 2 --json bench_out/independent_score.json
	OPENBLAS_NUM_THREADS=1 $(PY) benchmarks/predictor_check.py --replicates 30 --json bench_out/predictor_check.json
	OPENBLAS_NUM_THREADS=1 $(PY) benchmarks/rrw_point_bound.py --records 40
	OPENBLAS_NUM_THREADS=1 $(PY) benchmarks/gm_tau_coverage.py --cases 40 --json bench_out/gm_tau_coverage.json
	OPENBLAS_NUM_THREADS=1 $(PY) benchmarks/gm_null_tail.py --records 3000 --json bench_out/gm_null_tail.json

# mypy on src/gyroarray as it stands (pyproject's [tool.mypy]), ~20 s.
typecheck: $(STAMP)
	$(PY) -m mypy

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis reports/demo docs/_api
