# gyroarray — the two commands a newcomer runs: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test bench venv clean

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
	$(VENV)/bin/gyroarray design --plot reports/demo/design_gdop.png
	$(VENV)/bin/gyroarray simulate scenarios/examples/tetra_swing.toml --out reports/demo
	$(VENV)/bin/gyroarray allan reports/demo/tetra_swing.csv.gz --plot reports/demo/tetra_swing_adev.png
	@echo "demo: wrote reports/demo/design_gdop.png, reports/demo/tetra_swing.csv.gz (+ .toml) and reports/demo/tetra_swing_adev.png"

test: $(STAMP)
	$(PY) -m pytest -q
	$(VENV)/bin/gyroarray check

bench: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) benchmarks/run.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis reports/demo
