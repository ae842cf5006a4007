# make run  : set up .venv and run the simulator on the built-in default scene
# make test : set up .venv and run the whole test suite
# make bench: quick engine benchmark (not part of make test)
PYTHON ?= python3.11
VENV   ?= .venv
PY      = $(VENV)/bin/python
STAMP   = $(VENV)/.installed

.PHONY: run test bench setup clean

setup: $(STAMP)

$(STAMP): setup.py setup.cfg package.xml
	@command -v $(PYTHON) >/dev/null || { echo "$(PYTHON) not found (Python 3.11 needed)"; exit 1; }
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	touch $(STAMP)

run: $(STAMP)
	$(VENV)/bin/vplayground $(ARGS)

test: $(STAMP)
	$(PY) -m pytest -q test

bench: $(STAMP)
	$(PY) bench/pile.py

clean:
	rm -rf $(VENV) build *.egg-info
