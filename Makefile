VENV ?= .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
PMDCID := $(VENV)/bin/pmdcid
STAMP := $(VENV)/.installed
# the kernel compiled from its generated C (pmdcid/simulate/_kernel.c, written by
# `python -m pmdcid.export.codegen` from the kernel's Python source; built by setup.py, as a plain
# `pip install .` does); without it (no C compiler) numba's JIT serves, ~1 s slower per command
AOT := pmdcid/simulate/.kernel-built
AOT_SOURCES := pmdcid/simulate/_kernel.c setup.py

.PHONY: install test test-fast lint bench realbench fleetbench demo fixtures clean aot

# setuptools >= 77 in the venv too: $(AOT)'s `setup.py build_ext` reads pyproject.toml's SPDX
# licence with the venv's own setuptools (a Python 3.11 venv starts with 65, which refuses it)
$(STAMP): pyproject.toml
	test -x $(PY) || python3 -m venv $(VENV)
	$(PIP) install --quiet --upgrade pip 'setuptools>=77'
	$(PIP) install --quiet -e '.[test]'
	touch $(STAMP)

# then numba's cache of the same kernel filled (identify/jit_cache.py): the JIT's first compile,
# a minute and more, paid once here rather than by a first command or by the tests
$(AOT): $(STAMP) $(AOT_SOURCES)
	$(PY) setup.py -q build_ext --inplace
	$(PY) -m pmdcid.identify.jit_cache
	touch $(AOT)

aot: $(AOT)

install: $(STAMP) $(AOT)

test: $(STAMP) $(AOT)
	$(PY) -m pytest -n 2

test-fast: $(STAMP) $(AOT)
	$(PY) -m pytest -n 2 -m "not slow"

lint: $(STAMP)
	$(VENV)/bin/ruff check pmdcid tests bench docs/examples

bench: $(STAMP) $(AOT)
	$(PY) bench/run.py

realbench: $(STAMP) $(AOT)
	$(PY) bench/realbench.py --write docs/real-data.md

# a synthetic fleet of 24 units on local Dask clusters of 1 and 2 workers: units per hour, the
# scaling, the outliers and drifts found, the population priors' shorter tests (docs/fleet.md)
fleetbench: $(STAMP) $(AOT)
	$(PY) bench/fleet.py --priors

# the whole rig in one command (identify: every stage, the joint fit, diagnose, the report) on the
# bundled logs that carry an effect nobody declared; `pmdcid demo` shows the stages one by one
demo: $(STAMP) $(AOT)
	mkdir -p demo-output
	rm -f demo-output/model.json
	$(PMDCID) identify fixtures/hidden/*.csv -m demo-output/model.json --km 0.0502 \
		-o demo-output/report

fixtures: $(STAMP)
	$(PY) -m pmdcid.synth fixtures

clean:
	rm -rf $(VENV) demo-output .pytest_cache pmdcid/simulate/_kernel.*.so $(AOT)
