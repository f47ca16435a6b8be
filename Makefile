# uiogen — every target installs what it needs into .venv/ first.
#   make demo    main job: design + generate + build + runs; the page build/report/index.html (README)
#   make test    the test suite (CI runs this through .ci/run)
#   make test-fast  the fast lane: no build, compiler, QEMU, Dask or browser (pytest -m "not slow")
#   make misra   cppcheck's MISRA C:2012 addon on the generated C, against misra/kernel_deviations.toml
#   make embedded-tools  cppcheck, arm-none-eabi-gcc, qemu-system-arm (apt-get where available)
#   make check   reliability suite (hostile input, sanitizers, static facts, determinism) and the long runs
#   make docs    re-run demo and bench into docs/data/, rewrite the docs' tables, build the site
#   make generate | build | bench | clean   (bench: also campaign runs/s, 1 and 2 workers, 10,000 runs, and
#                                            every verb's latency against its floor; LATENCY=--quick: a few minutes)
#   make lock    refresh constraints.txt (exact versions of everything the targets install)
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
# Exact versions for every install (see the file's header; `make lock` refreshes it).
PIP    := $(BIN)/python -m pip --disable-pip-version-check
PIN    := -c constraints.txt
CC     ?= cc
# Options of make bench's latency table (python -m codegen.tools.latency --help), e.g. LATENCY=--quick
LATENCY ?=
export CC

.PHONY: all venv generate build demo test test-fast check bench docs clean lock misra embedded-tools

all: demo

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet $(PIN) pip setuptools wheel
	$(PIP) install --quiet $(PIN) --no-build-isolation -e '.[test,validation]'
	touch $@

venv: $(STAMP)

generate: $(STAMP)
	$(BIN)/uiogen generate

build: generate
	$(BIN)/uiogen build

demo: build
	$(BIN)/uiogen demo --report build/report

embedded-tools:
	sh scripts/install_embedded_tools.sh

# The suite CI runs: everything but the reliability suite and the long runs (make check runs those:
# hostile input to the compiled steps, sanitizers, static facts, byte-identical generation under another
# hash seed and another CPU, a generate killed at every file operation; 10^7 steps per observer, the
# random-model acceptance rate, every built-in through analyze). The typed-error tests of every user
# file, the killed-at-each-rename and concurrent-generate tests and the conformance checks stay here.
# Two workers (pytest-xdist) on a 2-core machine, a test module per worker at a time: module fixtures
# stay in one process, and the CPU-bound solves and compiles use both cores. The longest modules
# start first (tests/durations.json, in the order tests/conftest.py gives; xdist's own reorder is off).
test: build embedded-tools
	$(BIN)/python -m pytest -q -m "not long and not reliability" -n auto --dist loadfile --no-loadscope-reorder tests

# The fast lane: the venv only (no generate, no build): what a developer runs while working, on two
# workers like make test. A test that needs a compiled extension, a compiler, QEMU, Dask, mkdocs or a
# browser, or that runs for more than a few seconds, is marked slow.
test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -m "not slow" -n auto --dist loadfile --no-loadscope-reorder tests

misra: generate embedded-tools
	$(BIN)/python -m codegen.targets.misra

check: build embedded-tools
	$(BIN)/python -m pytest -q -m "reliability or long" -n auto --dist loadfile --no-loadscope-reorder tests

bench: build
	$(PIP) install --quiet $(PIN) --no-build-isolation -e '.[bench]'
	$(BIN)/uiogen bench
	$(BIN)/python -m codegen.campaign.bench --target
	$(BIN)/python -m codegen.tools.latency $(LATENCY)

# The docs: re-run the demo and the benchmark, rewrite the docs' tables from them, build the site.
docs: build
	$(PIP) install --quiet $(PIN) --no-build-isolation -e '.[bench]'
	mkdir -p docs/data
	$(BIN)/uiogen demo --json > docs/data/demo.json.tmp && mv docs/data/demo.json.tmp docs/data/demo.json
	$(BIN)/uiogen bench --json > docs/data/bench.json.tmp && mv docs/data/bench.json.tmp docs/data/bench.json
	$(BIN)/python -m codegen.tools.spread --out docs/data/spread.json
	$(BIN)/python -m codegen.tools.latency --out docs/data/latency.json
	mkdir -p docs/data/sweeps
	$(BIN)/uiogen sweep switched_pi_bank_angle --set 'design.pole_radius=[29, 30, 30.5, 35, 50, 100, 300, 1000, 10000]' \
	  --set 'design.decay_rate=[0, 1]' --show gamma,max_pole_modulus,max_pole_real_part,discrete_contraction_per_step \
	  --json > docs/data/sweeps/switched_pi_pole_radius.json
	$(BIN)/uiogen sweep lpv_linf_driver_torque --set 'design.gain_bound_times_sample_time=[1, 3, 7.63, 7.633, 10, 30, 100]' \
	  --show gamma,gamma_quadratic,discrete_kappa,discrete_contraction_per_step --json > docs/data/sweeps/linf_gain_bound.json
	for c in lpv_linf_driver_torque switched_pi_bank_angle; do \
	  $(BIN)/uiogen campaign docs/campaigns/$$c.toml --out docs/campaigns/$$c || exit 1; done
	$(BIN)/uiogen docs
	$(BIN)/mkdocs build --strict --quiet

# Refresh constraints.txt: the newest versions pyproject.toml allows, resolved in a scratch venv.
lock:
	rm -rf .venv-lock
	$(PYTHON) -m venv .venv-lock
	.venv-lock/bin/python -m pip install --quiet --upgrade pip setuptools wheel
	.venv-lock/bin/python -m pip install --quiet -e '.[test,validation,bench]'
	{ sed -n '/^#/p' constraints.txt; .venv-lock/bin/python -m pip freeze --all --exclude-editable; } > constraints.txt.new
	mv constraints.txt.new constraints.txt
	rm -rf .venv-lock

clean:
	rm -rf build .pytest_cache
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
