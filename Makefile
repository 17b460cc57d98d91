# cdh_planner: venv, demo, tests, benchmarks.
# `make demo` and `make test` work from a fresh clone: they build .venv themselves.

SHELL := /bin/bash
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# The ROS 2 interface packages of interfaces/, built with CMake into the venv.
IFACE_STAMP := $(VENV)/.interfaces
IFACE_SRC   := interfaces/build_in_venv.py $(shell find interfaces/*/ -type f 2>/dev/null)
# Prefer python3.11; fall back to python3.
PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)

# ROS isolation: discovery stays on this machine; ament_index finds the
# message definitions that the PyPI wheels install into the venv.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export AMENT_PREFIX_PATH := $(abspath $(VENV))
export PIP_DISABLE_PIP_VERSION_CHECK := 1

.PHONY: venv demo test bench pictures clean

venv: $(STAMP) $(IFACE_STAMP)

$(VENV)/bin/python:
	@test -n "$(PYTHON)" || { echo "python3.11 / python3 not found" >&2; exit 1; }
	$(PYTHON) -m venv $(VENV) || { rm -rf $(VENV); \
	  echo "venv creation failed: on Debian, apt-get install python3-venv (or python3.11-venv)" >&2; exit 1; }

# Always use the venv's own python (ros-wheels-bootstrapper re-execs it).
$(STAMP): $(VENV)/bin/python requirements.txt test/requirements-urdf.txt setup.py setup.cfg package.xml cdh_planner/manifold/kernels.py \
          cdh_planner/manifold/layout.py cdh_planner/manifold/aot.py cdh_planner/aot.py \
          cdh_planner/scene/kernels.py cdh_planner/scene/aot.py cdh_planner/model/shape_forms.py \
          $(addprefix cdh_planner/wrench/,kernel.py centred.py linalg.py compiled.py aot.py) \
          cdh_planner/model/elastic_kernel.py cdh_planner/model/elastic_aot.py \
          cdh_planner/accuracy_kernel.py cdh_planner/accuracy_aot.py cdh_planner/kernel_linalg.py \
          cdh_planner/trajectory/motion_kernel.py cdh_planner/trajectory/motion_aot.py \
          cdh_planner/compiled_json.py cdh_planner/compiled_json.c
	$(PY) -m pip install -r requirements.txt
	$(PY) -m pip install --no-deps -r test/requirements-urdf.txt
	$(PY) -m pip install -e .
	@# the F / F_x, the collision, the wrench, the elastic, the accuracy, the timing's motion kernels compiled ahead of time (first call
	@# ~10 ms instead of 0.4 - 1 s; without a C compiler this warms numba's JIT cache instead),
	@# verify's JSON reader and rows writer compiled from C (without a compiler: Python's, slower),
	@# and the package's bytecode (read even
	@# where PYTHONDONTWRITEBYTECODE=1 keeps Python from writing it)
	$(PY) -m cdh_planner.manifold.aot
	$(PY) -m cdh_planner.scene.aot
	$(PY) -m cdh_planner.wrench.aot
	$(PY) -m cdh_planner.model.elastic_aot
	$(PY) -m cdh_planner.accuracy_aot
	$(PY) -m cdh_planner.trajectory.motion_aot
	$(PY) -m cdh_planner.compiled_json
	$(PY) -m compileall -q cdh_planner
	touch $(STAMP)

# cdh_planner_interfaces (PlanPath, TensionEnvelope) and, unless a real one is importable, the
# copy of control_msgs' FollowJointTrajectory: first the pip-installed wheels' CMake files get
# this venv's include folders (they name the Python the wheels were built with), then a plain
# CMake build (build/interfaces/) installs each package into the venv.
$(IFACE_STAMP): $(STAMP) $(IFACE_SRC)
	$(PY) interfaces/build_in_venv.py --build-dir build/interfaces
	touch $(IFACE_STAMP)

demo: venv
	$(VENV)/bin/cdh-planner demo

test: venv
	$(PY) -m pytest

# Benchmark-only dependencies (OMPL for benchmarks/vs_ompl.py): only `make bench` installs them.
# Every benchmarks/*.py script runs; a module without a __main__ block (random_queries.py) is skipped.
bench: venv
	$(PY) -m pip install -r benchmarks/requirements.txt
	@set -e; shopt -s nullglob; files=(benchmarks/*.py); \
	if [ $${#files[@]} -eq 0 ]; then echo "no benchmarks/*.py"; fi; \
	for f in "$${files[@]}"; do grep -q '^if __name__ == "__main__":' "$$f" || continue; echo "== $$f"; $(PY) "$$f"; done

# Every picture of the README and the manual (docs/*.png), regenerated.
pictures: venv
	bash docs/pictures.sh

clean:
	rm -rf $(VENV) build install log .pytest_cache *.egg-info
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
