# Two entry points for a fresh machine: `make demo` and `make test`. Both bootstrap .venv (python3.11)
# idempotently and build the native core through the normal package build (scikit-build-core + nanobind).
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
PY     := $(BIN)/python
STAMP  := $(VENV)/.render-budget-installed
TEST_STAMP := $(VENV)/.render-budget-test-installed
NATIVE_SOURCES := $(shell find sim_core -name '*.cpp' -o -name '*.h' -o -name 'CMakeLists.txt' 2>/dev/null) \
                  CMakeLists.txt pyproject.toml
# A new Python package (or module turned package) changes the editable install's module map: reinstall.
PY_PACKAGES := $(shell find service sim_core/python -name '__init__.py' 2>/dev/null)
PYTEST_ARGS ?=

.PHONY: all venv test-venv test demo report lint native-tests sanitize bench scenes addon clean

all: venv

$(PY):
	$(PYTHON) -m venv $(VENV)

# The pins are read from pyproject.toml (tools/pins.py) so that versions stay in one place: the
# installer and build tools (tool.render-budget.bootstrap), the native build's requirements
# (build-system.requires). uv installs (pip only bootstraps it) and leaves bytecode to the first import.
# The product and bpy (the scene builds) are what `make demo` needs; the test and bench tools come on top,
# for the targets that run them. uv reuses its cached build of a local package until its pyproject.toml
# changes, so the stamp asks it to rebuild this one (ninja's build folder keeps that incremental); the
# test stamp then finds it installed and adds only the test extra. The stamps' lock is not .venv/.lock:
# uv locks that file itself while it installs.
PINS = $(PY) tools/pins.py
UV_INSTALL = $(BIN)/uv pip install -q --python $(PY)

$(STAMP): $(PY) $(NATIVE_SOURCES) $(PY_PACKAGES)
	flock $(VENV)/.render-budget.lock sh -c '\
	  $(PY) -m pip install -q $$($(PINS) installer) && \
	  $(UV_INSTALL) $$($(PINS) build) && \
	  $(UV_INSTALL) --no-build-isolation --refresh-package render-budget --reinstall-package render-budget -e ".[blender]"'
	touch $(STAMP)

$(TEST_STAMP): $(STAMP)
	flock $(VENV)/.render-budget.lock $(UV_INSTALL) --no-build-isolation -e ".[test]"
	touch $(TEST_STAMP)

venv: $(STAMP)

test-venv: $(TEST_STAMP)

test: test-venv
	$(PY) -m pytest $(PYTEST_ARGS)

demo: venv
	$(PY) -m tools.demo

# Every test scene (cached: a scene is rebuilt only when its generator changed).
scenes: venv
	$(PY) -m blend_scenes.build

# The installable Blender extension zip for this platform (dist/render_budget-<version>-<platform>.zip):
# this project's wheel (native core) and its runtime wheels in the manifest, then Blender's own build.
addon: venv
	$(PY) tools/build_extension.py --out dist/

# The main job on any scene: make report SCENE=chess
SCENE ?= teapot
report: venv
	$(PY) -m tools.demo --scene $(SCENE) --out out/$(SCENE)

# Benchmarks print their tables; bench/RESULTS.md records the quoted ones with their commands.
bench: test-venv
	for b in bench/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

lint: test-venv
	$(BIN)/ruff check .

# Standalone C++ tests (no Python), optionally under AddressSanitizer + UBSan.
native-tests: venv
	$(BIN)/cmake -S . -B build/native -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_MAKE_PROGRAM=$(abspath $(BIN)/ninja) && \
	  $(BIN)/cmake --build build/native && cd build/native && $(abspath $(BIN))/ctest --output-on-failure

sanitize: venv
	$(BIN)/cmake -S . -B build/sanitize -G Ninja -DSIM_CORE_SANITIZE=ON -DCMAKE_MAKE_PROGRAM=$(abspath $(BIN)/ninja) && \
	  $(BIN)/cmake --build build/sanitize && cd build/sanitize && $(abspath $(BIN))/ctest --output-on-failure

clean:
	rm -rf build out $(STAMP) $(TEST_STAMP)
