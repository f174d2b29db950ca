# Developer entry points. `make test` is what CI runs; `make demo` is the quick start.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
SUM    := $(shell cksum < pyproject.toml | cut -d' ' -f1)
# The whole toolchain (tests, ruff, mypy), installed editable: what `make test` needs.
DEV    := $(VENV)/.installed-dev-$(SUM)
# The runtime and the demo extra only (no dev tools), reinstalled when the sources change.
RUN    := $(VENV)/.installed-demo-$(SUM)
SOURCES := $(shell find bridge mappings -name '*.py' -o -name '*.yaml' -o -name py.typed)

.PHONY: test check lint demo docs clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

$(DEV): pyproject.toml | $(BIN)/python
	$(BIN)/pip install --quiet -e '.[dev]'
	rm -f $(VENV)/.installed-* && touch $@

$(RUN): pyproject.toml $(SOURCES) | $(BIN)/python
	$(BIN)/pip install --quiet '.[demo]'
	rm -f $(VENV)/.installed-demo-* && touch $@

# The suite mostly waits (brokers, buses, timeouts): four workers, one test file each at a
# time, make it three times quicker even on two cores. `make test PYTEST_ARGS=` runs serially.
PYTEST_ARGS ?= -n 4 --dist loadfile

test: $(DEV)
	$(BIN)/pytest $(PYTEST_ARGS)

check: $(DEV)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check bridge tests
	$(BIN)/mypy
	$(BIN)/lint-imports

# The five seed devices simulated, bridged to MQTT (a broker on 127.0.0.1:1883 if one
# answers, else an embedded one) with a live table. Ctrl-C stops. ARGS="--mqtt-url ...".
# A venv that `make test` set up already has everything; else runtime + demo extra only.
demo: $(if $(wildcard $(DEV)),$(DEV),$(RUN))
	$(BIN)/modbus-mqtt-bridge demo $(ARGS)

# docs/config.md is generated from the config schema (tests/test_docs.py checks it).
docs: $(DEV)
	$(BIN)/modbus-mqtt-bridge schema --markdown > docs/config.md

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .mypy_cache .ruff_cache
