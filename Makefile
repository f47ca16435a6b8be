# uiogen — every target installs what it needs into .venv/ first.
#   make demo    main job: design + generate + build + summary (README)
#   make test    the test suite (CI runs this through .ci/run)
#   make check   reliability suite (hostile input, sanitizers, static facts, determinism, long runs)
#   make generate | build | bench | clean
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
CC     ?= cc
export CC

.PHONY: all venv generate build demo test check bench clean

all: demo

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,validation]'
	touch $@

venv: $(STAMP)

generate: $(STAMP)
	$(BIN)/uiogen generate

build: generate
	$(BIN)/uiogen build

demo: build
	$(BIN)/uiogen demo

test: build
	$(BIN)/python -m pytest -q tests

check: build
	$(BIN)/python -m pytest -q -m reliability tests

bench: build
	$(BIN)/python -m pip install --quiet -e '.[bench]'
	$(BIN)/uiogen bench

clean:
	rm -rf python_bindings/_ext python_bindings/_build .pytest_cache
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
