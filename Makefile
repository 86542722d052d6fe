# Two commands set everything up: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: install demo test test-slow lint docs notebooks bench bench-gpu clean

install: $(STAMP)

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	@touch $(STAMP)

demo: install
	$(VENV)/bin/wardjax demo --out demo-output

# Two workers, whole test files per worker (module fixtures are computed once).
PYTEST_PAR ?= -n 2 --dist loadfile

# The default suite compiles many more programs than it runs for long (compiling is over half its CPU):
# XLA's CPU backend optimises the code less (same programs and arithmetic; XLA enables no fast-math at
# any level), about a fifth less CPU. The slow tests run long programs and keep the default level.
TEST_XLA_FLAGS ?= --xla_backend_optimization_level=0

test: install
	XLA_FLAGS="$(TEST_XLA_FLAGS) $(XLA_FLAGS)" $(PY) -m pytest -m "not slow" $(PYTEST_PAR)

test-slow: install
	$(PY) -m pytest -m slow $(PYTEST_PAR)

# ruff (lint + format check) and pyright, configured in pyproject.toml.
lint: install
	$(VENV)/bin/ruff check wardjax tests benchmarks
	$(VENV)/bin/ruff format --check wardjax tests benchmarks
	$(VENV)/bin/pyright

# The documentation site (MkDocs + mkdocstrings), warnings as errors, into site/.
docs: install
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict -d site
	$(PY) docs/_tools/check_site.py site

# Re-execute the notebooks in place, so that they are stored with their outputs.
notebooks: install
	$(PY) -m jupyter nbconvert --to notebook --execute --inplace notebooks/*.ipynb

bench: install
	$(PY) -m benchmarks

# Engine and texture benchmarks on a GPU (fits/s, evaluations/s, synthesis time); skips without one.
bench-gpu: install
	$(PY) -m benchmarks.gpu

clean:
	rm -rf $(VENV) demo-output .pytest_cache site
