"""The communication watchdog the bridge keeps fed (soft starter, Vacon board)."""

from __future__ import annotations

from bridge.core.watchdog import LEAD, Watchdog


def test_nothing_is_due_before_the_first_answer() -> None:
    dog = Watchdog(20.0)
    assert dog.due() is None
    assert dog.lapse(1000.0) is None


def test_a_keepalive_is_due_half_an_interval_after_the_last_answer() -> None:
    dog = Watchdog(20.0)
    assert dog.answered(100.0) is False
    assert dog.due() == 100.0 + LEAD * 20.0 == 110.0
    dog.answered(105.0)
    assert dog.due() == 115.0


def test_a_silence_longer_than_the_interval_is_reported_once_and_its_end_once() -> None:
    dog = Watchdog(2.0)
    dog.answered(10.0)
    assert dog.lapse(11.9) is None
    assert dog.lapse(12.0) is None  # exactly the interval: still fed
    assert dog.lapse(12.5) == 2.5
    assert dog.lapse(20.0) is None  # reported already
    assert dog.answered(21.0) is True  # the lapse ended
    assert dog.answered(21.5) is False
    assert dog.lapse(24.0) == 2.5  # a new silence, reported again
