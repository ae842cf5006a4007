# make run  : set up .venv and run the simulator node on the built-in default scene
# make test : set up .venv and run the whole test suite (a worker per core)
# make bench: this engine against Rapier, Jolt, PyBullet and MuJoCo, and the node's overhead; then the
#             falling phase of two piles beside Rapier and Jolt, on one thread and on two (minutes;
#             not in make test; the Rust peers build first, bench-peers, and are skipped without cargo)
# make fuzz : the hostile-input tests with FUZZ_EXAMPLES (default 5000) per property, randomised
# make soak : the node under steady traffic for DURATION seconds (default 1200), a Foxglove client
#             subscribed to everything (SOAK_ARGS= drops it); memory, RTF, late ticks
PYTHON ?=
VENV   ?= .venv
PY      = $(VENV)/bin/python
STAMP   = $(VENV)/.installed

FUZZ_EXAMPLES ?= 5000
DURATION      ?= 1200
SOAK_ARGS     ?= --foxglove

.PHONY: run test bench bench-peers fuzz soak setup interfaces clean FORCE

setup: $(STAMP)

# The venv's Python, chosen at every make (tools/choose_python: PYTHON= if given, else the one
# that imports a sourced ROS install's rclpy, else python3.11 for the Jazzy wheels; one line
# says which). A venv another Python made (ROS sourced after the first make, or no longer) is
# made again: its rclpy would not import. pyvenv.cfg changes only then, so an unchanged make
# installs nothing.
$(VENV)/pyvenv.cfg: FORCE
	@choice=$$(PYTHON='$(PYTHON)' sh tools/choose_python) || exit 1; \
	exe=$${choice#* }; \
	if [ $${choice%% *} = ros ]; then site=true; else site=false; fi; \
	grep -qxF "executable = $$exe" $@ 2>/dev/null && grep -qx "include-system-site-packages = $$site" $@ \
		&& exit 0; \
	if [ -f $@ ]; then \
		was="the PyPI wheels"; grep -qx "include-system-site-packages = true" $@ && was="a sourced rclpy"; \
		echo "make: $(VENV) was made by $$(sed -n 's/^executable = //p' $@) for $$was: making it again"; \
		rm -rf $(VENV); fi; \
	set -- $(VENV); if [ $$site = true ]; then set -- --system-site-packages $(VENV); fi; \
	echo "$$exe -m venv $$*"; "$$exe" -m venv "$$@"

# The engine's first compile (jit_cache.compile_once: a process and its helpers fill the cache,
# other processes wait for it) needs only the engine's requirements: the set-up starts it as soon
# as they are in and installs the ROS wheels and builds the interface packages meanwhile, so that
# `make test` and `make run` find the engine compiled.
$(STAMP): setup.py setup.cfg package.xml interfaces/simulation_interfaces/package.xml interfaces/tf2_msgs/package.xml $(VENV)/pyvenv.cfg
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	@echo "make: compiling the engine (a minute or two, once) while the ROS packages install and build"; \
	$(PY) -c "from vplayground_ros.physics import World; World()" >$(VENV)/engine_compile.log 2>&1 & \
	engine=$$!; trap 'kill $$engine 2>/dev/null; exit 130' INT TERM; \
	{ $(PY) -c "import rclpy" 2>/dev/null || $(PY) -m pip install --quiet -e ".[ros]"; } \
		&& $(MAKE) --no-print-directory interfaces; built=$$?; \
	wait $$engine || { echo "make: the engine did not compile:"; cat $(VENV)/engine_compile.log; exit 1; }; \
	exit $$built
	touch $(STAMP)

# The interface packages no wheel brings: simulation_interfaces (the standard services, README
# "The standard simulation services") and tf2_msgs (/tf over ROS). On the PyPI wheels, built
# from interfaces/ into the venv (~1 min, once); with a ROS install sourced, the distro's
# packages. Without them the node serves and publishes everything else.
interfaces: $(VENV)/pyvenv.cfg
	@if grep -qx "include-system-site-packages = true" $(VENV)/pyvenv.cfg; then \
		$(PY) -c "import simulation_interfaces, tf2_msgs" 2>/dev/null || echo "make: apt install \
	ros-$$ROS_DISTRO-simulation-interfaces ros-$$ROS_DISTRO-tf2-msgs for the standard services and /tf"; \
	else $(PY) tools/build_interfaces.py || echo "make: the node runs without the standard \
	simulation_interfaces services or /tf over ROS"; fi

# The built-in Foxglove server is on under make run (FOXGLOVE= turns it off).
FOXGLOVE ?= --foxglove
run: $(STAMP)
	$(VENV)/bin/vplayground $(FOXGLOVE) $(ARGS)

# A worker per core (pytest-xdist; TEST_WORKERS= sets how many, at most 16): the suite mostly
# waits on the nodes it starts (4.6 -> 2.3 minutes on 2 cores); each worker on a DDS domain of
# its own (test/conftest.py), each test file on one worker in its order (its tests share the
# file's node, as they do in one process).
TEST_WORKERS ?= auto
test: $(STAMP)
	$(PY) -m pytest -q -n $(TEST_WORKERS) --maxprocesses 16 --dist loadfile test

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
	$(PY) bench/falling.py --threads 2

clean:
	rm -rf $(VENV) build *.egg-info
