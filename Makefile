# formation-match — the two commands a user needs: `make run-formation` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: setup run-formation run-formations test lint bench bench-voting view clean

# a .venv whose python is gone (a half-made one) or that is not this folder's (made before the
# clone was moved or copied: it imports the old folder's code, and its formation-match runs the
# old folder's python) is made again; one of a Python older than 3.11, or without pip, is named
# with what to do (make clean, then PYTHON=...). The check finds where the .venv's python would
# import pipeline from without running it (an error in the code does not remake the .venv). A PYTHON that is not a command, that
# does not run (a pyenv shim of a version not selected exits 127), or older than 3.11, is named before any .venv is made from it.
VENV_HERE = test -x $(PY) && (cd / && "$(CURDIR)/$(PY)" -c 'import importlib.util as u, os, sys; s = u.find_spec("pipeline"); sys.exit(s is None or os.path.realpath(s.origin) != os.path.realpath(sys.argv[1]))' "$(CURDIR)/pipeline/__init__.py") >/dev/null 2>&1
ifeq ($(shell $(VENV_HERE) && echo ok),)
  $(shell rm -f $(STAMP))
endif

$(STAMP): pyproject.toml
	@$(VENV_HERE) || { rm -rf $(VENV); \
	  command -v "$(PYTHON)" >/dev/null 2>&1 || { echo "error: PYTHON='$(PYTHON)' is not a command; formation-match needs Python 3.11 or newer: make PYTHON=python3.11 (or newer, or its path)" >&2; exit 1; }; \
	  $(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' >/dev/null 2>&1; rc=$$?; \
	  [ $$rc = 0 ] || [ $$rc = 1 ] || { echo "error: PYTHON='$(PYTHON)' does not run (exit $$rc: $$($(PYTHON) --version 2>&1 | head -1)); formation-match needs Python 3.11 or newer: make PYTHON=python3.11 (or newer, or its path)" >&2; exit 1; }; \
	  [ $$rc = 0 ] || { echo "error: PYTHON='$(PYTHON)' is $$($(PYTHON) --version 2>&1 | head -1); formation-match needs 3.11 or newer: make PYTHON=python3.11 (or newer)" >&2; exit 1; }; \
	  $(PYTHON) -m venv $(VENV); }
	@$(PY) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || { echo "error: $(VENV) holds Python $$($(PY) -c 'import sys; print(sys.version.split()[0])'); formation-match needs 3.11 or newer: make clean, then make PYTHON=python3.11 (or newer)" >&2; exit 1; }
	@$(PY) -m pip --version >/dev/null 2>&1 || $(PY) -m ensurepip --upgrade >/dev/null 2>&1 || { echo "error: $(VENV) has no pip (on Debian: apt install python3-venv); make clean, then again" >&2; exit 1; }
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

# the suite on TEST_WORKERS processes (pytest-xdist): two use both cores of a 2-core machine;
# make test TEST_WORKERS=0 runs it in one process
TEST_WORKERS ?= 2
test: $(STAMP)
	$(PY) -m pytest -n $(TEST_WORKERS)

lint: $(STAMP)
	$(PY) -m ruff check pipeline data_synth viz tests bench

# make bench: every bench script (each prints how long it took). make bench QUICK=1: three of the
# quicker ones, images_vs_colmap with --quick (the 640 px Sceaux copy of tests/data and one
# rendered ring, not the full-size photographs)
QUICK_BENCH := bench/run_formation.py bench/foundation.py "bench/images_vs_colmap.py --quick"
# bench/opencv_floor.py is not a bench of its own: bench/run_formation.py runs it on its images
ALL_BENCH := $(filter-out bench/opencv_floor.py,$(sort $(wildcard bench/*.py)))
bench: $(BENCH_STAMP)
	@if [ -n "$(QUICK)" ]; then set -- $(QUICK_BENCH); echo "quick bench (a few minutes): $$*"; \
	else set -- $(ALL_BENCH); echo "full bench: every script in bench/, several minutes each for the voting and scale ones; make bench QUICK=1 runs three of the quicker ones"; fi; \
	for b in "$$@"; do echo "== $$b"; start=$$(date +%s); $(PY) $$b || exit 1; \
	echo "== $$b took $$(( $$(date +%s) - start )) s"; done

bench-voting: $(BENCH_STAMP)
	$(PY) bench/voting_table1.py && $(PY) bench/voting_fig23.py && $(PY) bench/voting_pipeline.py

# make view [RUN=runs/DIR or FILE.rrd]: native viewer with a display, else the web viewer (its URL,
# with the recording's address, printed; python -m viz.browser checks it in headless Chromium)
# RUN is passed as one argument, as typed: single-quoted for the shell, its own quotes escaped,
# its text taken unexpanded (a '$' in a folder name is no make variable)
view: $(STAMP)
	$(PY) -m viz.view $(if $(value RUN),'$(subst ','\'',$(value RUN))')

clean:
	rm -rf $(VENV) runs .pytest_cache
