# `make demo` and `make test` create .venv on first use (and again when pyproject.toml changes).
# `make test`: ruff (lint + import order), mypy, the documentation site (mkdocs --strict, into the ignored site/),
# then pytest (the CPU-bound tests, the pinned diagnosis answers again on a generic CPU target, the integration tests).
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed
# numba caches a compiled function beside its module and checks only that module's file: a caller compiled in another
# module keeps the old code of a kernel edited since. Editing any module with compiled code clears every cache.
NUMBA_SOURCES := $(shell grep -rl --include='*.py' njit estimator recorded slave master teleop live study benchmarks 2>/dev/null)
NUMBA_STAMP := .numba-sources

.PHONY: demo test bench clean

$(STAMP): pyproject.toml
	test -x $(VENV)/bin/python || $(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --upgrade pip
	$(VENV)/bin/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

$(NUMBA_STAMP): $(NUMBA_SOURCES)
	find . -path ./$(VENV) -prune -o \( -name '*.nbi' -o -name '*.nbc' \) -type f -exec rm -f {} +
	touch $(NUMBA_STAMP)

demo: $(STAMP) $(NUMBA_STAMP)
	$(VENV)/bin/teleop demo

# The pinned diagnosis answers are checked again with numba compiling for a generic x86-64 CPU (no AVX2, no AVX-512,
# its own cache): the answers hold whatever vector width the machine has.
PINNED := tests/estimator/test_diagnosis_pinned.py

# pytest runs the CPU-bound tests on both cores (pytest-xdist; a worker that runs out of
# tests takes queued ones from the other, so one long file does not hold the pass), then the integration tests (real
# processes with 1 kHz loops over Zenoh) one at a time, alone on the machine, because their timing figures are what they check.
test: $(STAMP) $(NUMBA_STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --site-dir site
	$(VENV)/bin/python -m pytest -q -m "not integration" -n 2 --dist worksteal
	NUMBA_CPU_NAME=generic NUMBA_CACHE_DIR=.numba-generic $(VENV)/bin/python -m pytest -q -n 2 $(PINNED)
	$(VENV)/bin/python -m pytest -q -m integration

bench: $(STAMP) $(NUMBA_STAMP)
	$(VENV)/bin/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) runs site .pytest_cache $(NUMBA_STAMP) .numba-generic
	find . \( -name '*.nbi' -o -name '*.nbc' \) -type f -exec rm -f {} +
