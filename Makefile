# SymRay. `make test` and `make render` work on a fresh machine: each creates the
# pinned virtual environments it needs (.venv: Python 3.13 + bpy 5.2.3, the main
# one; .venv311: Python 3.11 + numpy 1.26 + bpy 4.2, the oldest supported Blender).
SHELL := /bin/bash
PY313 := $(shell tools/find_python 3.13)
PY311 := $(shell tools/find_python 3.11)
VENV := .venv
VENV311 := .venv311
PY := $(VENV)/bin/python
PYOLD := $(VENV311)/bin/python
export BLENDER_USER_RESOURCES ?= $(CURDIR)/.blender-user
PYTEST_FLAGS ?= -n 2 -q

.PHONY: test test-main test-oldest lint venv venv311 clean extension render

test: lint test-main test-oldest

$(VENV)/.stamp: requirements-dev.txt
	rm -rf $(VENV) && $(PY313) -m venv $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check -r requirements-dev.txt
	touch $@

$(VENV311)/.stamp: requirements-oldest.txt
	rm -rf $(VENV311) && $(PY311) -m venv $(VENV311)
	$(PYOLD) -m pip install -q --disable-pip-version-check -r requirements-oldest.txt
	touch $@

venv: $(VENV)/.stamp
venv311: $(VENV311)/.stamp

lint: venv
	$(VENV)/bin/ruff check .

test-main: venv
	$(PY) -m pytest $(PYTEST_FLAGS) tests

test-oldest: venv311
	$(PYOLD) -m pytest $(PYTEST_FLAGS) tests

clean:
	rm -rf $(VENV) $(VENV311) .blender-user dist out .pytest_cache

# The Blender extension: dist/symray-<version>.zip, built and validated by Blender's own
# extension tool (blender_ext.py build/validate from the bpy wheel).
EXT_VERSION := $(shell sed -n 's/^version = "\(.*\)"/\1/p' blender_manifest.toml)
EXT_ZIP := dist/symray-$(EXT_VERSION).zip
RENDER_ARGS ?=

extension: venv
	$(PY) tools/build_extension.py --output-dir dist

# Install the zip into the isolated user folder $(BLENDER_USER_RESOURCES), enable it and
# render the default scene (examples/render_scene.py) to out/default.png and .exr.
render: extension
	$(PY) tools/install_extension.py $(EXT_ZIP)
	mkdir -p out
	$(PY) examples/render_scene.py --out out/default.png --exr out/default.exr $(RENDER_ARGS)
