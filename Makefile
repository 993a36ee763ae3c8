# formation-match — the two commands a user needs: `make run-formation` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: setup run-formation run-formations test lint bench bench-voting view clean

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	@touch $(STAMP)

setup: $(STAMP)

run-formation: $(STAMP)
	$(PY) -m pipeline run-formation

run-formations: $(STAMP)
	$(PY) -m pipeline run-formations

test: $(STAMP)
	$(PY) -m pytest

lint: $(STAMP)
	$(PY) -m ruff check pipeline data_synth viz tests bench

bench: $(STAMP)
	@for b in bench/*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

bench-voting: $(STAMP)
	$(PY) bench/voting_table1.py && $(PY) bench/voting_fig23.py && $(PY) bench/voting_pipeline.py

view: $(STAMP)
	@last=$$(ls -td runs/*/recording.rrd 2>/dev/null | head -n 1); \
	if [ -z "$$last" ]; then echo "no recording yet: run 'make run-formation' first"; exit 1; fi; \
	echo "opening $$last"; $(VENV)/bin/rerun "$$last"

clean:
	rm -rf $(VENV) runs .pytest_cache
