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

.PHONY: setup demo test lint bench test-blender42 test-blender45 clean

$(VENV)/.synced: $(LOCK)
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet uv==0.13.8
	$(UV) pip sync --quiet --python $(PY) $(LOCK)
	touch $@

setup: $(VENV)/.synced

demo: setup
	$(PY) -m compositing.demo --out $(OUT)/demo

lint: setup
	$(VENV)/bin/ruff check .

test: setup
	$(VENV)/bin/ruff check .
	$(PY) -m pytest -q

bench: setup
	$(PY) -m benchmarks --out benchmarks/results --charts docs

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
