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

.PHONY: test test-main test-oldest lint venv venv311 clean extension render figures bench \
	bench-quick stress bench-perf bench-memory bench-honesty bench-presets \
	bench-viewport bench-f12 bench-cluster bench-scaling

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

# ruff (rules, and one formatter: `ruff format`, applied to the whole tree) and mypy on core/
lint: venv
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/mypy -p core

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

# The seed's figures (examples/figures.py) as PNGs in out/figures/; FIGURES_ARGS="--size 256"
# for bigger images. Error against run time (benchmarks/work_precision.py): `make bench` in
# full, `make bench QUICK=1` or `make bench-quick` in minutes; results in out/bench/.
# Stiff and extreme cases (benchmarks/stress.py): `make stress`.
FIGURES_ARGS ?=
BENCH_ARGS ?=
STRESS_ARGS ?=

figures: venv
	PYTHONPATH=. $(PY) examples/figures.py $(FIGURES_ARGS)

bench: venv
	PYTHONPATH=. $(PY) benchmarks/work_precision.py $(if $(QUICK),--quick) $(BENCH_ARGS)

bench-quick: venv
	PYTHONPATH=. $(PY) benchmarks/work_precision.py --quick $(BENCH_ARGS)

stress: venv
	PYTHONPATH=. $(PY) benchmarks/stress.py $(STRESS_ARGS)

# Performance figures of issue #6 next to their targets (benchmarks/bench_perf.py): quick in a
# few minutes; `make bench-perf FULL=1` adds the 1920x1080 frames and the error constants;
# PERF_ARGS="--baseline DIR" the speed-up over a checkout of the baseline (benchmarks/image_quality.py BASELINE).
PERF_ARGS ?=

bench-perf: venv
	PYTHONPATH=. $(PY) benchmarks/bench_perf.py $(if $(FULL),--full) $(PERF_ARGS)

# The adaptive sampler's promise (tolerance_px, an honest error pass) on 8 scenes against dense
# dopri5 references (benchmarks/honesty.py), ~5 min; HONESTY_ARGS="--quick": ~2.5 min.
HONESTY_ARGS ?=

bench-honesty: venv
	PYTHONPATH=. $(PY) benchmarks/honesty.py $(HONESTY_ARGS)

# The black hole presets' framing and their cost at 1920x1080 Preview (benchmarks/presets.py,
# issue #24), ~2 min; PRESETS_ARGS="--size 960x540 --quality FINAL".
PRESETS_ARGS ?=

bench-presets: extension
	$(PY) tools/install_extension.py $(EXT_ZIP)
	$(PY) benchmarks/presets.py $(PRESETS_ARGS)

# F12 (bpy.ops.render.render) beside the add-on's own job (benchmarks/f12.py, issue 51):
# F12_ARGS="--size 1920x1080 --scenes FACTORY,KERR_DISK".
F12_ARGS ?= --size 1920x1080
bench-f12: extension
	$(PY) tools/install_extension.py $(EXT_ZIP)
	$(PY) benchmarks/f12.py $(F12_ARGS)

# A frame on the process pool beside the same frame on a Dask LocalCluster, and a 3x3
# sweep (benchmarks/cluster.py, issue 49): CLUSTER_ARGS="--width 1920 --height 1080".
CLUSTER_ARGS ?= --width 1920 --height 1080 --sweep out/sweep
bench-cluster: venv
	PYTHONPATH=. $(PY) benchmarks/cluster.py $(CLUSTER_ARGS)

# Per-tile times of a 1080p frame and the pool simulated at 1..32 workers
# (benchmarks/scaling.py, issue 47): SCALING_ARGS="--quality preview --measure".
SCALING_ARGS ?= --quality preview,final
bench-scaling: venv
	PYTHONPATH=. $(PY) benchmarks/scaling.py $(SCALING_ARGS)

# The Rendered viewport's costs against issue 25's targets (benchmarks/viewport.py): the
# Kerr-with-disk preset in a 960x540 view; VIEWPORT_ARGS="--size 1920x1080 --turns 1,5".
VIEWPORT_ARGS ?=
bench-viewport: extension
	$(PY) tools/install_extension.py $(EXT_ZIP)
	$(PY) benchmarks/viewport.py $(VIEWPORT_ARGS)

# Peak memory against resolution, issue #13 (benchmarks/bench_memory.py): Preview at 1080p
# and 4K in ~2 min; MEMORY_ARGS="--sizes 1920x1080,7680x4320 --presets preview,final".
MEMORY_ARGS ?=

bench-memory: venv
	PYTHONPATH=. $(PY) benchmarks/bench_memory.py $(MEMORY_ARGS)
