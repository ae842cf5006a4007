# make run  : set up .venv and run the simulator node on the built-in default scene
# make test : set up .venv and run the whole test suite
# make bench: this engine against Rapier, Jolt, PyBullet and MuJoCo, and the node's overhead (minutes;
#             not in make test; the Rust peers build first, bench-peers, and are skipped without cargo)
# make fuzz : the hostile-input tests with FUZZ_EXAMPLES (default 5000) per property, randomised
# make soak : the node under steady traffic for DURATION seconds (default 1200), a Foxglove client
#             subscribed to everything (SOAK_ARGS= drops it); memory, RTF, late ticks
PYTHON ?= python3.11
VENV   ?= .venv
PY      = $(VENV)/bin/python
STAMP   = $(VENV)/.installed

FUZZ_EXAMPLES ?= 5000
DURATION      ?= 1200
SOAK_ARGS     ?= --foxglove

.PHONY: run test bench bench-peers fuzz soak setup clean

setup: $(STAMP)

# A sourced ROS install's rclpy is reused (the venv sees its site packages); without one the
# Jazzy wheels come from PyPI.
$(STAMP): setup.py setup.cfg package.xml
	@command -v $(PYTHON) >/dev/null || { echo "$(PYTHON) not found (Python 3.11 needed)"; exit 1; }
	test -x $(PY) || if $(PYTHON) -c "import rclpy" 2>/dev/null; then \
		$(PYTHON) -m venv --system-site-packages $(VENV); else $(PYTHON) -m venv $(VENV); fi
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	$(PY) -c "import rclpy" 2>/dev/null || $(PY) -m pip install --quiet -e ".[ros]"
	touch $(STAMP)

# The built-in Foxglove server is on under make run (FOXGLOVE= turns it off).
FOXGLOVE ?= --foxglove
run: $(STAMP)
	$(VENV)/bin/vplayground $(FOXGLOVE) $(ARGS)

test: $(STAMP)
	$(PY) -m pytest -q test

fuzz: $(STAMP)
	VPLAYGROUND_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) $(PY) -m pytest -q -p no:logging test/test_fuzz.py

soak: $(STAMP)
	mkdir -p bench/results
	$(PY) bench/soak.py --duration $(DURATION) $(SOAK_ARGS) --output bench/results/soak_$$(date +%Y%m%d_%H%M%S).txt

# Rapier and Jolt, a Rust program each (bench/peers); a failed build only leaves them out of the bench.
bench-peers:
	-sh bench/peers/build.sh

bench: $(STAMP) bench-peers
	$(PY) -m pip install --quiet -e ".[bench]"
	$(PY) bench/compare.py

clean:
	rm -rf $(VENV) build *.egg-info
