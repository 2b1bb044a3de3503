# The two commands of the README. Both create .venv on first use and install the project into it.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-test

.PHONY: demo test check lint typecheck bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip

# PYTHONWARNINGS: setuptools prints a generic "Editable installation" notice on every editable install (take
# care with folders named like the package); it says nothing about this project, so it is filtered by its text
$(STAMP): pyproject.toml | $(BIN)/python
	PYTHONWARNINGS="ignore:Editable installation" $(BIN)/python -m pip install -q -e '.[test]'
	touch $@

demo: $(STAMP)
	$(BIN)/gtsam-dvl demo -o demo-output

lint: $(STAMP)
	$(BIN)/ruff check gtsam_dvl factors tests bench examples
	$(BIN)/ruff format --check -q gtsam_dvl factors tests bench examples

typecheck: $(STAMP)
	$(BIN)/mypy gtsam_dvl

test: lint typecheck
	$(BIN)/python -m pytest -n 2 --dist loadgroup -q

# the quick loop while editing: lint, types and the tests not marked slow
check: lint typecheck
	$(BIN)/python -m pytest -n 2 --dist loadgroup -q -m "not slow"

bench: $(STAMP)
	$(BIN)/python bench/bench_reader.py
	$(BIN)/python bench/bench_batch.py
	$(BIN)/python bench/bench_online.py
	$(BIN)/python bench/bench_compare.py

clean:
	rm -rf $(VENV) demo-output .pytest_cache .mypy_cache .ruff_cache
