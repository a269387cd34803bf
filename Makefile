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
OUT ?= out

.PHONY: extension scenes setup demo demo-compositing test test-blender lint bench bench-quick test-blender42 test-blender45 clean

$(VENV)/.synced: $(LOCK)
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet uv==0.13.8
	$(UV) pip sync --quiet --python $(PY) $(LOCK)
	touch $@

setup: $(VENV)/.synced

# The main job: render the bundled showcase with the Blender engine, composite it over the
# bundled backplate with our core and with Blender's Alpha Over, print errors and timings.
demo: setup
	$(PY) -m addon.demo --out $(OUT)/demo

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

# The trade-off families on small scenes (about 30 s), written outside the repository.
bench-quick: setup
	$(PY) -m benchmarks --quick --out $(OUT)/bench --charts $(OUT)/bench

# The Blender tests only (bpy 5.0.1).
test-blender: setup
	$(PY) -m pytest -q -m blender

# The installable extension zip (core packages vendored), validated by Blender's own CLI.
extension: setup
	$(PY) tools/build_extension.py --out dist

# Rebuild the sample .blend files (saved by Blender 4.2 so that 4.2, 4.5 and 5.0 open them).
scenes: $(VENV42)/.synced
	$(VENV42)/bin/python blend_files/make_scenes.py

$(VENV42)/.synced: $(LOCK42)
	test -x $(VENV42)/bin/python || $(PYTHON) -m venv $(VENV42)
	$(VENV42)/bin/python -m pip install --quiet uv==0.13.8
	$(VENV42)/bin/uv pip sync --quiet --python $(VENV42)/bin/python $(LOCK42)
	touch $@

# The Blender tests again, on Blender 4.2 LTS.
test-blender42: $(VENV42)/.synced
	$(VENV42)/bin/python -m pytest -q -m blender

$(VENV45)/.synced: $(LOCK45)
	test -x $(VENV45)/bin/python || $(PYTHON) -m venv $(VENV45)
	$(VENV45)/bin/python -m pip install --quiet uv==0.13.8
	$(VENV45)/bin/uv pip sync --quiet --python $(VENV45)/bin/python $(LOCK45)
	touch $@

# The Blender tests again, on Blender 4.5 LTS.
test-blender45: $(VENV45)/.synced
	$(VENV45)/bin/python -m pytest -q -m blender

clean:
	rm -rf $(VENV) $(VENV42) $(VENV45) $(OUT) .pytest_cache .ruff_cache
