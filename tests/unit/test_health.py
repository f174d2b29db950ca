"""Device health: offline after N failures, capped exponential backoff, back by itself."""

from __future__ import annotations

import pytest

from bridge.core.health import (
    DeviceHealth,
    Fault,
    HealthPolicy,
    Outcome,
    Transition,
    exception_meaning,
)
from bridge.core.protocol import ExceptionMeaning, Protocol

POLICY = HealthPolicy(offline_after=3, backoff_initial=5, backoff_max=40, backoff_factor=2)


def test_first_answer_brings_the_device_online() -> None:
    health = DeviceHealth(POLICY)
    assert health.online is None
    assert health.record(Outcome.OK, 0.0, latency=0.02) is Transition.ONLINE
    assert health.record(Outcome.OK, 1.0, latency=0.03) is None
    assert health.online is True
    assert health.last_latency == 0.03
    assert health.last_success == 1.0


def test_offline_after_n_consecutive_failures_then_backoff_doubles_to_the_cap() -> None:
    health = DeviceHealth(POLICY)
    health.record(Outcome.OK, 0.0)
    assert health.record(Outcome.TIMEOUT, 1.0) is None
    assert health.record(Outcome.TIMEOUT, 2.0) is None
    assert health.record(Outcome.TIMEOUT, 3.0) is Transition.OFFLINE
    assert health.online is False
    assert health.next_attempt == 8.0
    assert not health.may_poll(7.9)
    assert health.may_poll(8.0)
    backoffs = []
    now = 8.0
    for _ in range(5):
        assert health.record(Outcome.TIMEOUT, now) is None
        backoffs.append(health.backoff)
        now = health.next_attempt
    assert backoffs == [10, 20, 40, 40, 40]
    assert health.record(Outcome.OK, now) is Transition.ONLINE
    assert health.backoff == 0
    assert health.consecutive_failures == 0
    assert health.may_poll(now)


def test_busy_and_refused_prove_the_device_alive() -> None:
    health = DeviceHealth(POLICY)
    for now in range(10):
        health.record(Outcome.BUSY if now % 2 else Outcome.REFUSED, float(now), code=8)
    assert health.online is True
    assert health.busy == 5
    assert health.exceptions[8] == 10
    assert health.errors == 0


def test_failure_exceptions_count_towards_offline() -> None:
    health = DeviceHealth(POLICY)
    for now in range(3):
        transition = health.record(Outcome.FAILED, float(now), code=4)
    assert transition is Transition.OFFLINE
    assert health.timeouts == 0
    assert health.errors == 3


def test_counters_and_latency_percentiles() -> None:
    health = DeviceHealth(POLICY)
    assert health.percentile(0.5) is None
    for i in range(1, 101):
        health.record(Outcome.OK, float(i), latency=i / 1000)
    health.record(Outcome.TIMEOUT, 200.0)
    assert health.requests == 101
    assert health.timeouts == 1
    assert health.percentile(0.5) == 0.05
    assert health.percentile(0.95) == 0.095


@pytest.mark.parametrize(
    ("code", "declared", "name", "action"),
    [
        (2, {}, "illegal data address", "refused"),
        (6, {}, "server device busy", "busy"),
        (4, {}, "server device failure", "fail"),
        (0x42, {}, "not a standard code", "fail"),  # shown as exception 66 (not a ...)
        (
            8,
            {8: ExceptionMeaning(name="busy (EEPROM write)", action="busy")},
            "busy (EEPROM write)",
            "busy",
        ),
        (4, {4: ExceptionMeaning(name="CRC error", action="retry")}, "CRC error", "retry"),
    ],
)
def test_exception_meaning_prefers_the_device_manual(
    code: int, declared: dict, name: str, action: str
) -> None:
    meaning = exception_meaning(code, Protocol(exceptions=declared))
    assert (meaning.name, meaning.action) == (name, action)


def test_a_device_without_its_mapping_is_offline_at_once_with_the_reason() -> None:
    """A SunSpec device whose walk failed: offline with the reason, the next verdict says
    nothing new, and its first answer (with a built mapping) brings it online."""
    health = DeviceHealth(POLICY)
    assert health.unmapped(0.0, "not a SunSpec device: no marker") is Transition.OFFLINE
    assert health.online is False
    assert health.fault is Fault.UNMAPPED
    assert health.offline_reason(0.0) == "(not a SunSpec device: no marker)"
    assert health.unmapped(1.0, "SunSpec walk failed: timeout") is None
    assert health.offline_reason(1.0) == "(SunSpec walk failed: timeout)"
    assert health.record(Outcome.OK, 2.0, latency=0.01) is Transition.ONLINE
    assert health.fault is None
