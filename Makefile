# Two entry points (see README): `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: venv demo test clean

venv: $(STAMP)

$(STAMP): requirements.lock pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements.lock
	$(PY) -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP)

# Render the default preset (forward method, 60 s) into out/ and print its report.
demo: $(STAMP)
	$(VENV)/bin/hud-trace render hud-direct --method forward --seconds 60 --seed 1 --out out/hud-direct
	cat out/hud-direct/report.json

test: $(STAMP)
	$(PY) -m pytest -q

clean:
	rm -rf $(VENV) out

# The Blender extension: dist/hud_tracer-<version>.zip, built and validated with Blender's own tool.
BLENDER_EXT = $(VENV)/lib/python3.11/site-packages/bpy/4.5/scripts/addons_core/bl_pkg/cli/blender_ext.py

.PHONY: extension
extension: $(STAMP)
	$(PY) tools/fetch_wheels.py
	mkdir -p dist
	$(PY) $(BLENDER_EXT) build --source-dir . --output-dir dist
	$(PY) $(BLENDER_EXT) validate dist/hud_tracer-0.1.0.zip

# Speed against accuracy: charts in docs/, CSVs in benchmarks/results/ (about 15 minutes on 2 cores).
.PHONY: bench
bench: $(STAMP)
	$(PY) -m pip install --quiet -r requirements-bench.lock
	$(PY) benchmarks/convergence.py
	$(PY) benchmarks/throughput.py --seconds 20
	$(PY) benchmarks/eyebox.py --half 90 30 --step 10
