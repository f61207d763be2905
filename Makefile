# Two entry points (see README): `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
# The tracer and its charts (requirements.lock); the tests add pytest, bpy and Dask (requirements-test.lock).
STAMP := $(VENV)/.installed
TEST_STAMP := $(VENV)/.installed-test

.PHONY: venv demo test test-quick clean

venv: $(STAMP)

$(STAMP): requirements.lock pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet -r requirements.lock
	$(PY) -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP)

$(TEST_STAMP): $(STAMP) requirements-test.lock
	$(PY) -m pip install --quiet -r requirements-test.lock
	touch $(TEST_STAMP)

# Render the default preset (backward method with next-event estimation, 60 s) into out/hud-direct and
# print its readouts.
demo: $(STAMP)
	$(VENV)/bin/hud-trace render hud-direct --method backward --seconds 60 --seed 1 --out out/hud-direct
	$(VENV)/bin/hud-trace readouts out/hud-direct

# Two pytest processes share the tests, a file at a time (pytest-xdist); the tests marked serial (wall-time
# bounds, stop signals, every core in use) then run alone. More processes: make test PARALLEL="-n 4".
PARALLEL ?= -n 2 --dist loadfile

test: $(TEST_STAMP)
	$(PY) -m pytest -q $(PARALLEL) -m "not serial"
	$(PY) -m pytest -q -m serial

# The tests not marked slow: at most 3 minutes on 2 cores, for everyday work.
test-quick: $(TEST_STAMP)
	$(PY) -m pytest -q $(PARALLEL) -m "not slow and not serial"
	$(PY) -m pytest -q -m "not slow and serial"

clean:
	rm -rf $(VENV) out

# The Blender extension: one zip per platform, dist/hud_tracer-<version>-<platform>.zip, built with Blender's
# own tool (blender_ext.py build --split-platforms --source-dir . --output-dir dist) after tools/fetch_wheels.py,
# each zip validated (blender_ext.py validate) and its size printed: tools/build_extension.py, which the add-on
# tests build through too.
BLENDER_EXT = $(VENV)/lib/python3.11/site-packages/bpy/4.5/scripts/addons_core/bl_pkg/cli/blender_ext.py

.PHONY: extension
extension: $(TEST_STAMP)
	$(PY) tools/build_extension.py --blender-ext $(BLENDER_EXT) --output-dir dist

# The add-on tests (tests/addon/) on the oldest bpy the manifest allows (blender_version_min 4.2.0):
# bpy 4.2.23, the latest 4.2 patch on PyPI, in its own .venv-bpy42 from requirements-bpy42.lock (the pins
# of requirements.lock and requirements-test.lock but bpy). Not part of `make test` or .ci/run: the venv
# takes a 350 MB download and about 45 s, the 37 add-on tests about 3 minutes on 2 cores.
VENV42 := .venv-bpy42
STAMP42 := $(VENV42)/.installed

$(STAMP42): requirements-bpy42.lock pyproject.toml
	test -x $(VENV42)/bin/python || $(PYTHON) -m venv $(VENV42)
	$(VENV42)/bin/python -m pip install --quiet --upgrade pip
	$(VENV42)/bin/python -m pip install --quiet -r requirements-bpy42.lock
	$(VENV42)/bin/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP42)

.PHONY: test-bpy-oldest
test-bpy-oldest: $(STAMP42)
	$(VENV42)/bin/python -m pytest -q tests/addon

# Speed against accuracy: charts in docs/images/, CSVs in benchmarks/results/ (about 55 minutes on 2 cores: references,
# 7 presets x 4 method variants x 31 s of budgets, Mitsuba's 7 x 2 x 31 s, the throughput runs (the
# unpolarised model and hud-direct's default, 6 minutes each), the eyebox scan
# and the two hud-screen renders of docs/images/hud-screen-variants.png; then polarisation: Mitsuba's polarised variant
# on a windshield and a panel, 3 minutes, the cost of polarised transport, 3 minutes, and forward tracing per
# windshield ghost order, 3 minutes).
# Mitsuba 3 as a peer (benchmarks/mitsuba_peer.py): its llvm variant needs LLVM 19 (Debian's LLVM 14/15
# crash it), installed here when missing; without root or apt-get it runs the scalar variant and says so.
LLVM19 = ls /usr/lib/*/libLLVM.so.19* 2>/dev/null | head -n 1

.PHONY: bench
bench: $(TEST_STAMP)
	$(PY) -m pip install --quiet -r requirements-bench.lock
	$(PY) benchmarks/convergence.py
	@test -n "$$($(LLVM19))" || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null && \
		{ apt-get install -y -qq libllvm19 || { apt-get update -qq && apt-get install -y -qq libllvm19; }; }; } || \
		echo "bench: libllvm19 could not be installed (needs root and apt-get): Mitsuba runs its scalar variant"
	DRJIT_LIBLLVM_PATH="$$($(LLVM19))" $(PY) benchmarks/mitsuba_peer.py
	$(PY) benchmarks/gather.py
	$(PY) benchmarks/fused_kernel.py
	$(PY) benchmarks/throughput.py --seconds 10 --repeats 3 --polarisation off
	$(PY) benchmarks/throughput.py --seconds 10 --repeats 3
	$(PY) benchmarks/eyebox.py --half 90 30 --step 10
	$(PY) benchmarks/screen_variants.py --seconds 120
	$(PY) benchmarks/mitsuba_polarised.py --spp 8192
	$(PY) benchmarks/polarisation_cost.py --seconds 8 --repeats 3
	$(PY) benchmarks/ghost_orders.py --rays 1e8
