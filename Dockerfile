# modbus-mqtt-bridge container image.
#
#   docker build -t modbus-mqtt-bridge .
#
# Check a config, then run the bridge with it. config.yaml is your own file (start from
# examples/rtu-serial.yaml or examples/tcp.yaml); the check needs neither the adapter nor
# the broker:
#
#   docker run --rm --network none -v "$PWD/config.yaml:/config/config.yaml:ro" \
#       modbus-mqtt-bridge check -c /config/config.yaml
#   docker run -d --name modbus-bridge --restart unless-stopped --network host \
#       -v "$PWD/config.yaml:/config/config.yaml:ro" \
#       --device /dev/ttyUSB0 --group-add "$(stat -c %g /dev/ttyUSB0)" modbus-mqtt-bridge
#
# --network host lets the config's mqtt://127.0.0.1:1883 reach a broker on this host
# (without it, 127.0.0.1 is the container itself: give the broker's LAN address instead,
# mqtt://192.168.1.10:1883). --group-add gives the bridge the group that owns the adapter
# on this host (dialout, gid 20 on Debian, Ubuntu and Raspberry Pi OS). docker-compose.yml
# runs the bridge next to its own Mosquitto instead (deploy/config.yaml).
#
# Two stages on the same base image:
#   build    builds the project wheel and collects the wheels of its dependencies, then
#            installs exactly those wheels (no source tree, no index) into /opt/venv, a
#            venv without pip or setuptools;
#   runtime  python:3.11-slim plus that venv: no compiler, no build backend, no wheels,
#            no source, running as an unprivileged user.
# The venv is copied rather than built in place so that no wheel file stays behind in a
# layer; it only works because both stages share the same base (same /usr/local/bin/python).

ARG PYTHON_IMAGE=python:3.11-slim

# --- build ----------------------------------------------------------------------------
FROM ${PYTHON_IMAGE} AS build

ENV PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_NO_CACHE_DIR=1

WORKDIR /src
# Only what the wheel is built from (see .dockerignore): the package, the shipped
# mappings (packaged as bridge/mappings) and the metadata pyproject.toml points at.
COPY pyproject.toml README.md ./
COPY bridge ./bridge
COPY mappings ./mappings

# Every dependency is published as a wheel for linux/amd64 and linux/arm64, so no build
# tools are needed; --only-binary makes a missing wheel fail loudly instead of compiling.
# The venv gets no pip of its own (--without-pip): the base image's pip installs into it.
RUN pip wheel --wheel-dir /wheels --only-binary=:all: --no-binary=modbus-mqtt-bridge . \
 && python -m venv --without-pip /opt/venv \
 && pip --python /opt/venv/bin/python install --no-index --find-links=/wheels modbus-mqtt-bridge \
 && /opt/venv/bin/modbus-mqtt-bridge mappings list

# --- runtime --------------------------------------------------------------------------
FROM ${PYTHON_IMAGE} AS runtime

# The package version, passed by whoever builds (.ci/release image: --build-arg
# VERSION=<bridge.__version__>, the one place it is written; empty otherwise), and the base
# image, as built (docker build --build-arg PYTHON_IMAGE=...).
ARG VERSION
ARG PYTHON_IMAGE
LABEL org.opencontainers.image.title="modbus-mqtt-bridge" \
      org.opencontainers.image.description="Modbus RTU/TCP field devices to MQTT and Home Assistant: typed entities, safe writes, decoded alarms." \
      org.opencontainers.image.version="${VERSION}" \
      org.opencontainers.image.licenses="MIT" \
      org.opencontainers.image.source="https://github.com/modbus-mqtt-bridge/modbus-mqtt-bridge" \
      org.opencontainers.image.url="https://github.com/modbus-mqtt-bridge/modbus-mqtt-bridge" \
      org.opencontainers.image.documentation="https://github.com/modbus-mqtt-bridge/modbus-mqtt-bridge#readme" \
      org.opencontainers.image.base.name="${PYTHON_IMAGE}"

# An unprivileged user in the dialout group, which owns serial devices (/dev/ttyUSB*,
# /dev/ttyAMA*) on Debian-style hosts. A device passed with --device keeps the host's
# group id; if the host's dialout is not gid 20, add that gid with --group-add.
RUN groupadd --system --gid 10001 bridge \
 && useradd --system --uid 10001 --gid bridge --groups dialout \
        --home-dir /nonexistent --no-create-home --shell /usr/sbin/nologin bridge

COPY --from=build /opt/venv /opt/venv

ENV PATH=/opt/venv/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    BRIDGE_HEALTH_URL=http://127.0.0.1:9464/health

# Bind-mount the config file here (or a folder with it, your own mapping files, whose
# paths in the config are relative to it, and the MQTT password file if you use one).
# No VOLUME: an anonymous volume per container would hold nothing.
WORKDIR /config
# Numeric, so that runtimes can verify it is not root (Kubernetes runAsNonRoot); the
# uid alone keeps the supplementary dialout group of the passwd entry.
USER 10001

# Prometheus metrics (config bridge.metrics: {enabled: true, host: 0.0.0.0, port: 9464}),
# and the web page (bridge.web: {enabled: true, host: 0.0.0.0, token_env: ...}).
EXPOSE 9464 8099

# Health = the bridge process is alive and serving: it answers on its metrics endpoint.
# /health is served on the bridge's own event loop, in the task group that also runs the
# MQTT session and its reconnect loop (bridge/metrics.py), so a crashed bridge or a
# blocked loop fails the check, which `modbus-mqtt-bridge check` (a config validation) or
# a "PID 1 exists" test would not. A bus that is down does not fail it: restarting the
# container brings no unplugged gateway back and takes every other device offline each
# time. Bus and device state stay in <base>/bridge/health, the diagnostic entities, the
# web page and GET /health/buses (503 with the reason while a bus is down, for a monitor
# that wants it); /health names the buses down in its answer (docker inspect shows it
# under .State.Health.Log).
# It needs bridge.metrics.enabled: true in the config (host 127.0.0.1 is enough for the
# check, 0.0.0.0 to let Prometheus scrape it); set BRIDGE_HEALTH_URL for another port.
# Without metrics, turn the check off (compose: healthcheck: {disable: true}).
# Plain python + urllib: the slim image has no curl or wget, and none is added.
HEALTHCHECK --interval=30s --timeout=5s --start-period=30s --retries=3 \
    CMD ["python", "-c", "import os, sys, urllib.error, urllib.request\ntry:\n    print(urllib.request.urlopen(os.environ['BRIDGE_HEALTH_URL'], timeout=4).read().decode(errors='replace'), end='')\nexcept urllib.error.HTTPError as refused:\n    sys.exit(refused.read().decode(errors='replace'))\nexcept OSError as failed:\n    sys.exit(f'no answer from the bridge: {failed}')"]

ENTRYPOINT ["modbus-mqtt-bridge"]
CMD ["run", "-c", "/config/config.yaml"]
