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

.PHONY: test test-cluster test-other-python test-ha check lint demo docs clean esphome soak

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

# Three sites on a 3-node NATS cluster, each node killed in turn (tests/integration/
# test_cluster.py, marked `cluster`: a few minutes, so not in `make test`); skipped, saying
# so, without nats-server.
test-cluster: $(DEV)
	$(BIN)/pytest -p no:xdist -p no:cacheprovider -m cluster -rsxX tests/integration/test_cluster.py

# The stop races again on a newer Python (asyncio's cancellation changed in 3.12 and 3.13:
# a fix that holds on one may not on the other), in a venv of its own. Found in pyenv by
# default; OTHER_PYTHON=/path/to/python3.x to choose; said and skipped when there is none.
OTHER_PYTHON ?= $(lastword $(sort $(wildcard $(HOME)/.pyenv/versions/3.13*/bin/python3.13)))
OTHER_VENV   := .venv-other
OTHER_TESTS  ?= tests/integration/test_stop_race.py tests/integration/test_stop.py \
	tests/integration/test_mqtt_farewell.py

test-other-python:
ifeq ($(OTHER_PYTHON),)
	@echo "test-other-python: no Python 3.13 found (set OTHER_PYTHON); skipped"
else
	test -x $(OTHER_VENV)/bin/pytest || { $(OTHER_PYTHON) -m venv $(OTHER_VENV) && \
		$(OTHER_VENV)/bin/pip install --quiet --upgrade pip; }
	$(OTHER_VENV)/bin/pip install --quiet -e '.[test]'
	$(OTHER_VENV)/bin/python --version
	$(OTHER_VENV)/bin/pytest -p no:cacheprovider -n 2 --dist loadfile $(OTHER_TESTS)
endif

# The bridge against real Home Assistant, the oldest supported release and the current one
# (slow, so not in `make test`): each installed once under .ha/ (tools/ha_env.sh: a Debian
# testing chroot with Python 3.13 and 3.14, one venv per version; needs root and Debian's
# apt), then per version tools/check_ha_discovery.py on the discovery snapshots and the
# extreme states (tools/ha_check.sh) and tests/ha (a headless Home Assistant on a private
# broker: entity ids, the documented ids, a clean log over start, config change and stop).
# a machine-wide cache (3 GB): a fresh clone on the same machine (CI) finds it built
HA_ROOT     ?= $(HOME)/.cache/modbus-mqtt-bridge/ha-forky
HA_VERSIONS ?= 2025.10.4 2026.11.0

test-ha: $(DEV)
	tools/ha_env.sh $(HA_ROOT) $(HA_VERSIONS)
	for version in $(HA_VERSIONS); do \
		tools/ha_check.sh $(HA_ROOT) $$version $(BIN)/python || exit 1; \
		HA_ROOT=$(HA_ROOT) HA_VERSION=$$version \
			$(BIN)/pytest -p no:cacheprovider -p no:xdist tests/ha -q -rs || exit 1; \
	done

# ESPHome's own config validation for the ESPHome import (tests/importer/
# test_esphome_check.py, skipped saying so without it): ESPHome wants Python 3.12+ and
# brings platformio (about 220 MB, 80 s to install), so it gets a venv of its own in the
# machine-wide cache, made once by `make esphome` (.ci/run does) and found there by the
# tests; the bridge never needs it at run time (`import esphome` runs the `esphome` on PATH).
ESPHOME_VERSION ?= 2026.10.0
ESPHOME_VENV    ?= $(HOME)/.cache/modbus-mqtt-bridge/esphome
ESPHOME_PYTHON  ?= $(firstword $(wildcard /usr/bin/python3.13 /usr/bin/python3.12 \
	$(HOME)/.pyenv/versions/3.13*/bin/python3.13 $(HOME)/.pyenv/versions/3.12*/bin/python3.12))

esphome:
ifeq ($(ESPHOME_PYTHON),)
	@echo "esphome: no Python 3.12+ found (set ESPHOME_PYTHON); the ESPHome checks are skipped"
else
	$(ESPHOME_VENV)/bin/esphome version 2>/dev/null | grep -q ' $(ESPHOME_VERSION)$$' || { \
		rm -rf $(ESPHOME_VENV) && $(ESPHOME_PYTHON) -m venv $(ESPHOME_VENV) && \
		$(ESPHOME_VENV)/bin/pip install --quiet --upgrade pip && \
		$(ESPHOME_VENV)/bin/pip install --quiet esphome==$(ESPHOME_VERSION); }
endif

# A month of a site's faults in DURATION (5m, 1h; bench/soak_faults.py, issue 38): the bridge
# in its own process against the simulated seed devices and a meter, on Modbus TCP and on an
# RTU line (a pty pair), with a private mosquitto; broker kills and stalls, device reboots and
# silences, line noise, reloads, gateway masters, HA restarts and command bursts on a seeded
# schedule (SEED repeats one); the invariants are checked as it runs; any violation: exit 1.
DURATION ?= 1h
SEED     ?= 1
soak: $(DEV)
	$(BIN)/python bench/soak_faults.py $(DURATION) --seed $(SEED)

check: $(DEV)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check bridge tests
	$(BIN)/mypy
	$(BIN)/lint-imports

# The release steps of .github/workflows/release.yml, here, publishing nothing: the
# versions, actionlint, sdist + wheel, the wheel in a fresh venv checking the examples, the
# image (this machine's architecture without buildx), a local registry standing in for
# ghcr.io, the add-on built from it exactly as the Supervisor builds it (.ci/release).
# Docker: ../shared/tools/docker-local.sh starts an engine here.
release-check:
	.ci/release all

# The tests on a real Docker engine (the image, compose, the add-on on a Supervisor-like
# network); skipped, saying why, when no engine answers. .ci/run starts one first.
DOCKER_TESTS ?= tests/test_docker.py tests/test_addon_docker.py
test-docker: $(DEV)
	$(BIN)/pytest -p no:xdist -p no:cacheprovider $(DOCKER_TESTS)

# The five seed devices simulated, bridged to MQTT (a broker on 127.0.0.1:1883 if one
# answers, else an embedded one) with a live table. Ctrl-C stops. ARGS="--mqtt-url ...".
# A venv that `make test` set up already has everything; else runtime + demo extra only.
demo: $(if $(wildcard $(DEV)),$(DEV),$(RUN))
	$(BIN)/modbus-mqtt-bridge demo $(ARGS)

# docs/config.md is generated from the config schema (tests/test_docs.py checks it), docs/library.md
# from the mappings' library blocks (tests/library/test_library_doc.py).
docs: $(DEV)
	$(BIN)/modbus-mqtt-bridge schema --markdown > docs/config.md
	$(BIN)/python tools/library_doc.py > docs/library.md

clean:
	rm -rf $(VENV) $(OTHER_VENV) .ha build *.egg-info .pytest_cache .mypy_cache .ruff_cache
