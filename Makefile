# Developer entry points. `make test` is what CI runs; `make demo` is the quick start.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-$(shell cat pyproject.toml | cksum | cut -d' ' -f1)

.PHONY: test check lint demo docs clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	rm -f $(VENV)/.installed-* && touch $@

test: $(STAMP)
	$(BIN)/pytest

check: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check bridge tests
	$(BIN)/mypy
	$(BIN)/lint-imports

# The five seed devices simulated, bridged to MQTT (a broker on 127.0.0.1:1883 if one
# answers, else an embedded one) with a live table. Ctrl-C stops. ARGS="--mqtt-url ...".
demo: $(STAMP)
	$(BIN)/modbus-mqtt-bridge demo $(ARGS)

# docs/config.md is generated from the config schema (tests/test_docs.py checks it).
docs: $(STAMP)
	$(BIN)/modbus-mqtt-bridge schema --markdown > docs/config.md

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .mypy_cache .ruff_cache
