"""Reconnect delays: short while an outage is young, longer later, reset by a good session."""

from __future__ import annotations

import pytest

from bridge.core.backoff import ReconnectBackoff


def delays(backoff: ReconnectBackoff, times: list[float]) -> list[float]:
    return [backoff.failed(t) for t in times]


def test_a_young_outage_is_retried_often() -> None:
    backoff = ReconnectBackoff()
    assert delays(backoff, [0.0, 0.1, 0.3, 0.7, 1.1, 1.5, 30.0]) == pytest.approx(
        [0.1, 0.2, 0.4, 0.4, 0.4, 0.4, 0.4]
    )


def test_an_old_outage_backs_off_doubling_to_the_cap() -> None:
    backoff = ReconnectBackoff()
    delays(backoff, [0.0, 0.1, 0.3, 59.0])  # up to 0.4 s while the outage is young
    assert delays(backoff, [60.0, 61.0, 62.0, 70.0, 90.0, 200.0, 300.0]) == pytest.approx(
        [0.8, 1.6, 3.2, 6.4, 12.8, 25.6, 30.0]
    )


def test_a_good_session_starts_over() -> None:
    backoff = ReconnectBackoff()
    backoff.failed(0.0)
    for t in range(61, 200, 10):
        backoff.failed(float(t))
    backoff.connected(200.0)
    assert backoff.failed(215.0) == pytest.approx(0.1)  # 15 s of session: start over
    assert backoff.failed(215.1) == pytest.approx(0.2)


def test_a_session_dropped_at_once_does_not_start_over() -> None:
    backoff = ReconnectBackoff()
    backoff.failed(0.0)
    backoff.failed(0.1)  # 0.2
    backoff.connected(0.3)
    assert backoff.failed(0.35) == pytest.approx(0.4)  # kept growing
    backoff.failed(70.0)  # the outage is old now
    backoff.connected(71.0)
    assert backoff.failed(71.5) == pytest.approx(1.6)


def test_a_refused_login_is_not_retried_five_times_a_second() -> None:
    backoff = ReconnectBackoff()
    times = [0.0, 0.1, 0.3, 0.7, 1.5, 3.1, 6.3]
    delays_refused = [backoff.failed(t, refused=True) for t in times]
    assert delays_refused == pytest.approx([0.1, 0.2, 0.4, 0.8, 1.6, 3.2, 6.4])
