"""Device health beyond timeouts: a device answering only busy, or refusing every read."""

from __future__ import annotations

import pytest

from bridge.core.health import DeviceHealth, Fault, HealthPolicy, Outcome, Transition

POLICY = HealthPolicy(offline_after=3, backoff_initial=5, backoff_max=40, busy_offline_after=30)
OK, BUSY, REFUSED, TIMEOUT = Outcome.OK, Outcome.BUSY, Outcome.REFUSED, Outcome.TIMEOUT


def replay(answers: list[tuple[float, Outcome]]) -> tuple[DeviceHealth, list[Transition]]:
    health = DeviceHealth(POLICY)
    transitions = []
    for now, outcome in answers:
        transition = health.record(outcome, now)
        if transition is not None:
            transitions.append(transition)
    return health, transitions


@pytest.mark.parametrize(
    ("case", "answers", "online", "transitions"),
    [
        ("busy for a moment at start: there", [(0, BUSY), (1, BUSY), (2, OK)], True, ["online"]),
        ("busy a while, few answers", [(0, OK), (1, BUSY), (40, BUSY)], True, ["online"]),
        ("busy often, not long", [(0, OK)] + [(t / 10, BUSY) for t in range(1, 200)], True, ["online"]),
        ("only busy for 30 s", [(0, OK)] + [(t, BUSY) for t in range(1, 32)], False, ["online", "offline"]),
        ("only busy from the start", [(t, BUSY) for t in range(0, 31)], False, ["online", "offline"]),
        ("a value between resets it", [(0, BUSY), (20, BUSY), (25, OK), (29, BUSY), (45, BUSY), (50, BUSY)], True, ["online"]),
        ("busy, offline, answers again", [(t, BUSY) for t in range(0, 31)] + [(40, OK)], True, ["online", "offline", "online"]),
        ("busy probes keep it offline", [(t, BUSY) for t in range(0, 31)] + [(40, BUSY), (60, BUSY)], False, ["online", "offline"]),
        ("refused alone: not online", [(0, REFUSED), (1, REFUSED)], None, []),
        ("refused does not clear timeouts", [(0, OK), (1, TIMEOUT), (2, REFUSED), (3, TIMEOUT), (4, TIMEOUT)], False, ["online", "offline"]),
        ("busy does not clear timeouts", [(0, OK), (1, TIMEOUT), (2, BUSY), (3, TIMEOUT), (4, TIMEOUT)], False, ["online", "offline"]),
    ],
)  # fmt: skip
def test_busy_and_refused_answers_alone_never_keep_a_device_online_for_ever(
    case: str, answers: list[tuple[float, Outcome]], online: bool | None, transitions: list[str]
) -> None:
    health, seen = replay(answers)
    assert health.online is online, case
    assert seen == transitions, case


def test_answering_only_busy_goes_offline_with_the_reason_and_backs_off() -> None:
    health, _ = replay([(t, BUSY) for t in range(0, 31)])
    assert health.fault is Fault.BUSY
    assert health.offline_reason(30.0) == "after 30 s: answers only 'busy'"
    assert health.next_attempt == 35.0
    assert not health.may_poll(34.0)
    health.record(BUSY, 35.0)  # a probe answered busy: not back, the backoff doubles
    assert (health.online, health.backoff, health.next_attempt) == (False, 10.0, 45.0)
    assert health.errors == 0
    assert health.last_success is None
    assert health.record(OK, 45.0, latency=0.01) is Transition.ONLINE
    assert (health.fault, health.busy_streak) == (None, 0)


def test_polls_refused_as_a_whole_count_towards_offline() -> None:
    health = DeviceHealth(POLICY)
    health.record(OK, 0.0)
    for now in (1.0, 2.0):
        health.record(REFUSED, now, code=2)
        assert health.refuses_every_read(now) is None
    health.record(REFUSED, 3.0, code=2)
    assert health.refuses_every_read(3.0) is Transition.OFFLINE
    assert health.fault is Fault.REFUSES
    assert health.offline_reason(3.0) == "after 3 failed polls: refuses every read"
    assert (health.refusal_faults, health.exceptions[2], health.errors) == (3, 3, 0)
    assert health.next_attempt == 8.0
    assert health.refuses_every_read(8.0) is None  # a probe refused: the backoff doubles
    assert health.next_attempt == 18.0
    assert health.record(OK, 18.0) is Transition.ONLINE


def test_a_device_that_stops_answering_is_offline_after_failed_requests() -> None:
    health, _ = replay([(0, OK), (1, TIMEOUT), (2, TIMEOUT), (3, TIMEOUT)])
    assert health.fault is Fault.NO_ANSWER
    assert health.offline_reason(3.0) == "after 3 failed requests"
