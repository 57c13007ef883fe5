# pprender: the two commands of the README.
#   make demo   set up, then render the default BRDF pictures (the main job)
#   make test   set up, then cargo test + pytest (pytest-xdist: a worker per core, up to 4)
# Set-up is idempotent: apt/pip steps are skipped when their stamp is newer than the
# files that define them; the extension rebuild is incremental (cargo).

SHELL := /bin/bash
VENV  ?= .venv
PY    := $(VENV)/bin/python
STAMP := .stamps
# Debian packages: LLVM 15 for Mitsuba's LLVM variants (mitsuba 3.9.0 / drjit 1.4.0),
# Mesa's lavapipe + the Vulkan loader for the GPU-less renderer.
APT_PACKAGES := libllvm15 mesa-vulkan-drivers libvulkan1
export NODEVICE_SELECT := 1
export PYTHONHASHSEED := 0

.PHONY: setup build demo test test-rust test-python bench docs gpu-bundle clean

setup: $(STAMP)/apt $(STAMP)/pip build

$(STAMP)/apt: Makefile
	@mkdir -p $(STAMP)
	@missing=""; for p in $(APT_PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "apt: installing$$missing"; \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing; \
	fi
	@touch $@

$(VENV)/bin/python:
	python3 -m venv $(VENV)

$(STAMP)/pip: pyproject.toml | $(VENV)/bin/python
	@mkdir -p $(STAMP)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q "maturin>=1.16,<2"
	$(PY) -m pip install -q -r <($(PY) -c "import tomllib;d=tomllib.load(open('pyproject.toml','rb'))['project'];print('\n'.join(d['dependencies']+d['optional-dependencies']['test']))")
	@touch $@

build: $(STAMP)/pip
	@$(VENV)/bin/maturin develop --release --quiet

demo: setup
	$(PY) examples/demo.py

test-rust: $(STAMP)/apt
	cargo test --release --quiet

# pytest-xdist workers: one per core, at most 4 (each holds up to about 3 GB); a file's
# tests stay together on one worker (--dist loadfile: their module fixtures are made once)
PYTEST_WORKERS ?= $(shell n=$$(nproc 2>/dev/null || echo 1); [ $$n -gt 4 ] && n=4; echo $$n)

test-python: setup
	$(PY) -m pytest -q -n $(PYTEST_WORKERS) --dist loadfile

test: setup test-rust test-python

bench: setup
	$(PY) benchmarks/bench.py

docs: setup
	$(PY) scripts/seed_table.py
	$(PY) scripts/compare_microsurface.py

# the wheels and the Vulkan loader that scripts/gpu_check.sh installs on a bare GPU machine
gpu-bundle: setup
	scripts/gpu_bundle.sh

clean:
	rm -rf target $(STAMP) $(VENV)
