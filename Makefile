# The two commands of the README:
#   make run    set up, then run the main job on its default scene
#   make test   set up, then run the C++ unit tests and the default pytest tier (one pytest-xdist
#               worker per core, a test file's tests on one worker so that its module fixtures run once)
PYTHON := /usr/bin/python3
# The main job: the paper's case 3 with all of its physics (static excavation stage with the
# lining installed, Mohr-Coulomb rock around the cavern, concrete lining damage, oblique P + SV
# El Centro, interlayer contact with deterioration) on the coarse layered-cavern mesh: the
# static stage, then a 1 s filter lead-in (t < 0, record time) and the first 2 s of the record (its PGA
# is at 2.0 s).
# The scene's own duration is 3.9 s; the full comparison of the cases is workflows/case_study.py.
SCENE ?= workflows/scenes/case3_contact_coarse.toml
RUN_ARGS ?= --set time.duration=2.0

.PHONY: setup run test test-slow bench
setup:
	@bash scripts/setup.sh

run: setup
	$(PYTHON) -m pyfem run $(SCENE) $(RUN_ARGS)

test: setup
	ctest --test-dir build --output-on-failure
	$(PYTHON) -m pytest -q -rs -n auto --dist loadfile --durations=25

test-slow:
	@bash scripts/setup.sh --with-paraview
	$(PYTHON) -m pytest -q -rs -m slow

bench: setup
	$(PYTHON) -m pyfem bench
