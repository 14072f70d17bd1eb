# `make demo` and `make test` create .venv on first use (and again when pyproject.toml changes).
# `make test`: ruff (lint + import order); at once pytest on the CPU-bound tests, mypy, the documentation site (mkdocs
# --strict, into the ignored site/) and the pinned diagnosis answers on a generic CPU target; then the integration tests.
PYTHON ?= python3
# Python and pytest keep compiled bytecode (__pycache__, ignored by git) under make even where the environment sets
# PYTHONDONTWRITEBYTECODE: without it every process the suite starts compiles the project's modules from source
# again (0.3-0.5 s a start; the integration tests alone start over a hundred), and every pytest run rewrites the
# asserts of every test module it collects (about 9 s a run).
export PYTHONDONTWRITEBYTECODE :=
VENV := .venv
STAMP := $(VENV)/.installed
# numba caches a compiled function beside its module and checks only that module's file: a caller compiled in another
# module keeps the old code of a kernel edited since. Editing any module with compiled code clears every cache.
NUMBA_SOURCES := $(shell grep -rl --include='*.py' njit estimator recorded slave master teleop live study benchmarks 2>/dev/null)
NUMBA_STAMP := .numba-sources

.PHONY: demo test test-cpu test-types test-docs test-generic bench clean

# The project and its test tools are installed by uv (the versions pip would pick, in a quarter of pip's minute); where
# uv cannot install (an index only pip is configured for), pip does.
$(STAMP): pyproject.toml
	test -x $(VENV)/bin/python || $(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet uv && $(VENV)/bin/uv pip install --quiet --python $(VENV)/bin/python \
		-e '.[test]' || $(VENV)/bin/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

$(NUMBA_STAMP): $(NUMBA_SOURCES)
	find . -path ./$(VENV) -prune -o \( -name '*.nbi' -o -name '*.nbc' \) -type f -exec rm -f {} +
	touch $(NUMBA_STAMP)

demo: $(STAMP) $(NUMBA_STAMP)
	$(VENV)/bin/teleop demo

# The pinned diagnosis answers are checked again with numba compiling for a generic x86-64 CPU (no AVX2, no AVX-512,
# its own cache): the answers hold whatever vector width the machine has.
PINNED := tests/estimator/test_diagnosis_pinned.py

# `make test` runs ruff, then at once the CPU-bound tests on both cores (pytest-xdist; a worker that runs out of tests
# takes queued ones from the other, so one long file does not hold the pass) and, beside them, the checks that each keep
# one process busy: mypy, the documentation site (mkdocs --strict) and the pinned answers on a generic CPU. Each of
# those prints its output when it ends (--output-sync). Then the integration tests (real processes with 1 kHz loops
# over Zenoh) one at a time, alone on the machine, because their timing figures are what they check.
test: $(STAMP) $(NUMBA_STAMP)
	$(VENV)/bin/ruff check .
	@echo "make test: the CPU-bound tests, mypy, the documentation site and the pinned answers on a generic CPU at once"
	$(MAKE) --no-print-directory -j4 --output-sync=target test-cpu test-types test-docs test-generic
	$(VENV)/bin/python -m pytest -q -m integration

test-cpu: $(STAMP) $(NUMBA_STAMP)
	$(VENV)/bin/python -m pytest -q -m "not integration" -n 2 --dist worksteal

test-types: $(STAMP)
	$(VENV)/bin/mypy

test-docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --site-dir site

test-generic: $(STAMP) $(NUMBA_STAMP)
	NUMBA_CPU_NAME=generic NUMBA_CACHE_DIR=.numba-generic $(VENV)/bin/python -m pytest -q -p no:cacheprovider $(PINNED)

bench: $(STAMP) $(NUMBA_STAMP)
	$(VENV)/bin/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) runs site .pytest_cache $(NUMBA_STAMP) .numba-generic
	find . \( -name '*.nbi' -o -name '*.nbc' \) -type f -exec rm -f {} +
