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

# the bench extra (matplotlib, for the plots of two benches): only `make bench` needs it
BENCH_STAMP := $(VENV)/.installed-bench
$(BENCH_STAMP): $(STAMP)
	$(PY) -m pip install --quiet -e '.[dev,bench]'
	@touch $(BENCH_STAMP)

run-formation: $(STAMP)
	$(PY) -m pipeline run-formation

run-formations: $(STAMP)
	$(PY) -m pipeline run-formations

test: $(STAMP)
	$(PY) -m pytest

lint: $(STAMP)
	$(PY) -m ruff check pipeline data_synth viz tests bench

# make bench: every bench script (each prints how long it took; the full-size photo comparison
# is not among them: python bench/images_vs_colmap.py DIR). make bench QUICK=1: three quick ones,
# measured at 45 s (run_formation, 5 rounds, at a load average of 5), 15 s (foundation) and 65 s
# (images_vs_colmap on the 640 px Sceaux copy) on 2 cores
QUICK_BENCH := bench/run_formation.py bench/foundation.py bench/images_vs_colmap.py
bench: $(BENCH_STAMP)
	@if [ -n "$(QUICK)" ]; then set -- $(QUICK_BENCH); echo "quick bench (about 2 min): $$*"; \
	else set -- bench/*.py; echo "full bench: every script in bench/, several minutes each for the voting and scale ones; make bench QUICK=1 takes about 2 min"; fi; \
	for b in "$$@"; do echo "== $$b"; start=$$(date +%s); $(PY) $$b || exit 1; \
	echo "== $$b took $$(( $$(date +%s) - start )) s"; done

bench-voting: $(BENCH_STAMP)
	$(PY) bench/voting_table1.py && $(PY) bench/voting_fig23.py && $(PY) bench/voting_pipeline.py

# make view [RUN=runs/DIR or FILE.rrd]: native viewer with a display, else the web viewer (its URL,
# with the recording's address, printed; python -m viz.browser checks it in headless Chromium)
view: $(STAMP)
	$(PY) -m viz.view $(RUN)

clean:
	rm -rf $(VENV) runs .pytest_cache
