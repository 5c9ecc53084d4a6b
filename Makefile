VENV ?= .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
PMDCID := $(VENV)/bin/pmdcid
STAMP := $(VENV)/.installed

.PHONY: install test test-fast lint bench realbench demo fixtures clean

$(STAMP): pyproject.toml
	test -x $(PY) || python3 -m venv $(VENV)
	$(PIP) install --quiet --upgrade pip
	$(PIP) install --quiet -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -n 2

test-fast: $(STAMP)
	$(PY) -m pytest -n 2 -m "not slow"

lint: $(STAMP)
	$(VENV)/bin/ruff check pmdcid tests bench

bench: $(STAMP)
	$(PY) bench/run.py

realbench: $(STAMP)
	$(PY) bench/realbench.py --write docs/real-data.md

# the whole rig in one command (identify: every stage, the joint fit, diagnose, the report) on the
# bundled logs that carry an effect nobody declared; `pmdcid demo` shows the stages one by one
demo: $(STAMP)
	mkdir -p demo-output
	rm -f demo-output/model.json
	$(PMDCID) identify fixtures/hidden/*.csv -m demo-output/model.json --km 0.0502 \
		-o demo-output/report

fixtures: $(STAMP)
	$(PY) -m pmdcid.synth fixtures

clean:
	rm -rf $(VENV) demo-output .pytest_cache
