# Set-up and entry points. Every target creates its own virtual environment from the
# pinned lock file, so a fresh machine with Python 3.11 needs nothing else.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
UV := $(VENV)/bin/uv
LOCK := requirements/main.lock
VENV42 := .venv-blender42
LOCK42 := requirements/blender42.lock
VENV45 := .venv-blender45
LOCK45 := requirements/blender45.lock
# Blender 5.2 LTS embeds Python 3.13 and numpy 2 (bpy 5.2.3 on the package index).
# The first working 3.13 among python3.13 on PATH and pyenv's installed 3.13s (pyenv's shim fails
# unless 3.13 is a selected version).
PYTHON313 ?= $(shell for p in python3.13 $$(pyenv root 2>/dev/null)/versions/3.13*/bin/python3.13; do \
	"$$p" -c 'import sys; assert sys.version_info[:2] == (3, 13)' >/dev/null 2>&1 && { echo "$$p"; break; }; done)
VENV52 := .venv-blender52
LOCK52 := requirements/blender52.lock
OUT ?= out

.PHONY: extension extension-wheels test-extension scenes setup demo demo-compositing test test-blender lint bench bench-quick test-blender42 test-blender45 test-blender52 bench-preview clean

# The pinned packages, then this checkout itself in editable mode (no dependencies: the lock has
# them), so scripts in any directory import this checkout's packages with $(PY).
$(VENV)/.synced: $(LOCK) pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet uv==0.13.8
	$(UV) pip sync --quiet --compile-bytecode --python $(PY) $(LOCK)
	$(UV) pip install --quiet --no-deps --python $(PY) --editable .
	touch $@

setup: $(VENV)/.synced

# The main job: render the bundled showcase with the Blender engine, composite it over the
# bundled backplate with our core and with Blender's Alpha Over, print errors and timings;
# then the deep-compositing pair (a sphere through a pane) as deep OpenEXR files.
demo: setup
	$(PY) -m addon.demo --out $(OUT)/demo
	$(PY) -m compositing.deep_demo --out $(OUT)/demo/deep

# Every compositing operator on the two bundled sample images.
demo-compositing: setup
	$(PY) -m compositing.demo --out $(OUT)/demo-compositing

lint: setup
	$(VENV)/bin/ruff check .

test: setup
	$(VENV)/bin/ruff check .
	$(PY) -m pytest -q

bench: setup
	$(PY) -m benchmarks --out benchmarks/results --charts docs
	$(PY) -m benchmarks.planner_fuzz 200
	$(PY) -m benchmarks.cost_check
	$(PY) -m benchmarks.scene_fuzz 1000

# The trade-off families on small scenes (about 30 s), written outside the repository.
bench-quick: setup
	$(PY) -m benchmarks --quick --out $(OUT)/bench --charts $(OUT)/bench

# The Blender tests only (bpy 5.0.1).
test-blender: setup
	$(PY) -m pytest -q -m blender

# The installable extension zip (core packages vendored), validated by Blender's own CLI.
extension: setup
	$(PY) tools/build_extension.py --out dist

# The self-contained extension: numba, llvmlite, embreex and scipy bundled as wheels, one zip per
# Python ABI and platform (Blender 4.2–5.0 / Python 3.11 and 5.1+ / 3.13, e.g.
# dist/blinn_phong_render-0.1.0-blender4.2-5.0-python3.11-linux_x64.zip, ~114 MB).
# Wheels are downloaded by pip into ~/.cache/blinn-phong-render/wheels, never into the checkout.
PLATFORMS ?= linux-x64
extension-wheels: setup
	$(PY) tools/build_extension.py --wheels $(foreach p,$(PLATFORMS),--platform $(p)) --out dist

# The zip for one Blender (BLENDER_VERSION=4.2, 4.5, 5.0 or 5.2; default 5.0) installed into an
# environment with only that bpy (cached in ~/.cache/blinn-phong-render) and tested there. Slow, so
# opt-in: make test leaves it out; test-blender42/45/52 run it too.
BLENDER_VERSION ?= 5.0
EXT_VENV_4.2 := $(VENV42)
EXT_VENV_4.5 := $(VENV45)
EXT_VENV_5.0 := $(VENV)
EXT_VENV_5.2 := $(VENV52)
EXT_VENV = $(EXT_VENV_$(BLENDER_VERSION))
test-extension:
	@test -n "$(EXT_VENV)" || { echo "BLENDER_VERSION=$(BLENDER_VERSION): expected 4.2, 4.5, 5.0 or 5.2" >&2; exit 2; }
	$(MAKE) $(EXT_VENV)/.synced
	BLINN_PHONG_TEST_EXTENSION=1 $(EXT_VENV)/bin/python -m pytest -q tests/addon/test_addon_installed.py

# Material preview time at 128×128, compiled kernels against numpy.
bench-preview: setup
	$(PY) -m benchmarks.bench_preview --out $(OUT)/bench

# Rebuild the sample .blend files (saved by Blender 4.2 so that 4.2, 4.5 and 5.0 open them).
scenes: $(VENV42)/.synced
	$(VENV42)/bin/python blend_files/make_scenes.py

$(VENV42)/.synced: $(LOCK42)
	test -x $(VENV42)/bin/python || $(PYTHON) -m venv $(VENV42)
	$(VENV42)/bin/python -m pip install --quiet uv==0.13.8
	$(VENV42)/bin/uv pip sync --quiet --compile-bytecode --python $(VENV42)/bin/python $(LOCK42)
	touch $@

# The Blender tests again, on Blender 4.2 LTS, with the installed extension (test-extension).
test-blender42: $(VENV42)/.synced
	BLINN_PHONG_TEST_EXTENSION=1 $(VENV42)/bin/python -m pytest -q -m blender

$(VENV45)/.synced: $(LOCK45)
	test -x $(VENV45)/bin/python || $(PYTHON) -m venv $(VENV45)
	$(VENV45)/bin/python -m pip install --quiet uv==0.13.8
	$(VENV45)/bin/uv pip sync --quiet --compile-bytecode --python $(VENV45)/bin/python $(LOCK45)
	touch $@

# The Blender tests again, on Blender 4.5 LTS, with the installed extension (test-extension).
test-blender45: $(VENV45)/.synced
	BLINN_PHONG_TEST_EXTENSION=1 $(VENV45)/bin/python -m pytest -q -m blender

$(VENV52)/.synced: $(LOCK52)
	test -x $(VENV52)/bin/python || $(PYTHON313) -m venv $(VENV52)
	$(VENV52)/bin/python -m pip install --quiet uv==0.13.8
	$(VENV52)/bin/uv pip sync --quiet --compile-bytecode --python $(VENV52)/bin/python $(LOCK52)
	touch $@

# Blender 5.2 LTS (Python 3.13, numpy 2): the Blender tests (with the installed extension), then the
# core tests on numpy 2.
test-blender52: $(VENV52)/.synced
	BLINN_PHONG_TEST_EXTENSION=1 $(VENV52)/bin/python -m pytest -q -m blender
	$(VENV52)/bin/python -m pytest -q -m "not blender" tests/blinn_phong tests/compositing tests/effects tests/mesa tests/planning

clean:
	rm -rf $(VENV) $(VENV42) $(VENV45) $(VENV52) $(OUT) .pytest_cache .ruff_cache
