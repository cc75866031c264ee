# The two commands of the README:
#   make run    set up, then run the main job on its default scene
#   make test   set up, then run the C++ unit tests and the default pytest tier
PYTHON := /usr/bin/python3
SCENE ?= workflows/scenes/default.toml

.PHONY: setup run test test-slow bench
setup:
	@bash scripts/setup.sh

run: setup
	$(PYTHON) -m pyfem run $(SCENE)

test: setup
	ctest --test-dir build --output-on-failure
	$(PYTHON) -m pytest -q

test-slow:
	@bash scripts/setup.sh --with-paraview
	$(PYTHON) -m pytest -q -m slow

bench: setup
	$(PYTHON) -m pyfem bench
