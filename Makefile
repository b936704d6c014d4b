# Two commands set everything up on a fresh machine:
#   make demo   create .venv, install, run the pipeline on a generated synthetic scene
#   make test   create .venv, install, lint, run the test suite (what CI runs)
SHELL := /bin/bash
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
# Tests in two processes (pytest-xdist), a test file per process so that its module fixtures are
# built once: 6:49 against 11:08 in one process on these 2-core machines (session 16). The
# longest files first (tests/conftest.py's HEAVY_FIRST), not xdist's order by test count.
PYTEST_WORKERS ?= -n 2 --dist loadfile --no-loadscope-reorder
# One core per test process, the two already busy: one BLAS thread (OpenBLAS's extra threads
# spin; two processes side by side ran 1.5x slower with them, recon/parallel.py), and no
# processes forked for the tracker's start (`--workers`' default, MOCAP_WORKERS).
export OPENBLAS_NUM_THREADS ?= 1
export MOCAP_WORKERS ?= 1
# Shared libraries Open3D loads at import (libusb), for rendering (GL, EGL, OpenMP), and for its
# Filament renderer on the CPU (Vulkan loader + Mesa's lavapipe).
APT_PACKAGES := libusb-1.0-0 libgl1 libegl1 libgomp1 libvulkan1 mesa-vulkan-drivers

.PHONY: demo test test-all system-deps install lint bench clean

demo: install
	$(VENV)/bin/mocap demo

# Lint first: a commit that breaks `make lint` fails CI too (two did, session 30, unnoticed).
test: install lint
	@$(VENV)/bin/rerun analytics disable >/dev/null 2>&1 || true
	$(PY) -m pytest -q $(PYTEST_WORKERS)

test-all: install
	@$(VENV)/bin/rerun analytics disable >/dev/null 2>&1 || true
	$(PY) -m pytest -q -m '' $(PYTEST_WORKERS)

bench: install
	$(PY) benchmarks/sfm_overhead.py

lint: install
	$(VENV)/bin/ruff check recon tracking plugins tests benchmarks

install: system-deps $(VENV)/.installed

# Debian/Ubuntu only; other systems are left alone. Root installs, anyone else gets the line.
system-deps:
	@command -v dpkg >/dev/null 2>&1 || exit 0; \
	missing=""; \
	for p in $(APT_PACKAGES); do \
	  dpkg -s $$p 2>/dev/null | grep -q '^Status: install ok installed' || missing="$$missing $$p"; \
	done; \
	[ -z "$$missing" ] && exit 0; \
	if [ "$$(id -u)" = 0 ]; then \
	  echo "installing Debian packages:$$missing"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing >/dev/null; \
	else \
	  echo "Open3D needs Debian packages that are missing. Install them, then re-run make:"; \
	  echo "  sudo apt-get install -y$$missing"; \
	  exit 1; \
	fi

$(VENV)/.installed: pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev]'
	@touch $@

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache
