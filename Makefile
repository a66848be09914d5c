# The two commands a newcomer runs: `make run` (simulated MARTE) and `make test`.
# Both create .venv from pyproject.toml on first use.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: run test lint bench bench-quick fuzz soak clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

run: $(STAMP)
	$(VENV)/bin/ramp run --sim --config ramp.yaml --host 127.0.0.1

lint: $(STAMP)
	$(VENV)/bin/ruff check ramp firmware_like tests bench
	$(VENV)/bin/mypy

test: lint
	$(PY) -m pytest

bench: $(STAMP)
	$(PY) -m bench

bench-quick: $(STAMP)
	$(PY) -m bench --quick

fuzz: $(STAMP)
	RAMP_FUZZ_EXAMPLES=20000 $(PY) -m pytest tests/fuzz -q

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache .hypothesis
