"""Shared fixtures: private mosquitto brokers on free loopback ports (tests/integration/mosquitto.py)."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.integration.mosquitto import (
    Broker,
    TlsFiles,
    has_mosquitto,
    has_mosquitto_passwd,
    make_tls_files,
)

BROKER_USER, BROKER_PASSWORD = "bridge", "s3cret pass"


def _running(broker: Broker) -> Iterator[Broker]:
    if not has_mosquitto():
        pytest.skip("no /usr/sbin/mosquitto: apt-get install mosquitto (.ci/run does)")
    broker.start()
    try:
        yield broker
    finally:
        broker.stop()


@pytest.fixture
def mosquitto(tmp_path: Path) -> Iterator[Broker]:
    """An anonymous broker: ``url``, ``host``, ``port``, ``restart()``, ``stop()``."""
    yield from _running(Broker(tmp_path))


@pytest.fixture
def mosquitto_auth(tmp_path: Path) -> Iterator[Broker]:
    """A broker that only accepts BROKER_USER / BROKER_PASSWORD."""
    if not has_mosquitto_passwd():
        pytest.skip("mosquitto_passwd not installed (comes with the Debian package mosquitto)")
    yield from _running(Broker(tmp_path, users={BROKER_USER: BROKER_PASSWORD}))


@pytest.fixture(scope="session")
def tls_files(tmp_path_factory: pytest.TempPathFactory) -> TlsFiles:
    """One throwaway PKI per test session (making keys is the slow part)."""
    if shutil.which("openssl") is None:
        pytest.skip("the openssl CLI is needed to make test certificates")
    return make_tls_files(tmp_path_factory.mktemp("pki"))


@pytest.fixture
def mosquitto_tls(tmp_path: Path, tls_files: TlsFiles) -> Iterator[Broker]:
    """A broker speaking only TLS with a server certificate signed by ``tls_files.ca``."""
    yield from _running(Broker(tmp_path, tls=tls_files))


@pytest.fixture
def mosquitto_mtls(tmp_path: Path, tls_files: TlsFiles) -> Iterator[Broker]:
    """A TLS broker that also requires a client certificate signed by ``tls_files.ca``."""
    yield from _running(Broker(tmp_path, tls=tls_files, require_certificate=True))
