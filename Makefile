# Every target bootstraps .venv itself, so `make run` and `make test` work on a fresh machine.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp

.PHONY: run sweep test bench sim recordings clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	# compat: the checkout on sys.path by a plain .pth line; the default editable finder makes every
	# Python start-up ~25 ms longer, a window in which a Ctrl-C is Python's, not the station's
	$(PY) -m pip install -q -e '.[test]' --config-settings editable_mode=compat
	touch $(STAMP)

# The main job on the simulated rig: the terminal UI (a headless sweep: `make sweep`).
run: $(STAMP)
	$(VENV)/bin/station ui

sweep: $(STAMP)
	$(VENV)/bin/station run

# Two workers (pytest-xdist, a test file per worker: module fixtures stay shared); WORKERS=0 runs
# the suite in one process.
WORKERS ?= 2
test: $(STAMP)
	$(PY) -m pytest -q -p no:cacheprovider $(if $(filter-out 0,$(WORKERS)),-n $(WORKERS) --dist loadfile)

bench: $(STAMP)
	for b in bench/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

sim: $(STAMP)
	$(VENV)/bin/station sim

recordings: $(STAMP)
	$(VENV)/bin/station recordings --out recordings

clean:
	rm -rf $(VENV) build *.egg-info
