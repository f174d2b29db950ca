"""Reconnect delays: short while an outage is young, longer later, reset by a good session."""

from __future__ import annotations

import pytest

from bridge.core.backoff import BrokerUrls, ReconnectBackoff


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


# --- the next broker of a cluster (mqtt.url as a list) ----------------------------------


NODES = ["mqtt://a:1883", "mqtt://b:1883", "mqtt://c:1883"]


def test_one_broker_stays_and_waits_after_each_failure() -> None:
    nodes = BrokerUrls(["mqtt://a:1883"])
    assert [nodes.failed() for _ in range(3)] == [True, True, True]
    assert nodes.current == "mqtt://a:1883"


def test_a_dead_node_costs_one_reconnect_then_the_round_waits() -> None:
    nodes = BrokerUrls(NODES)
    assert nodes.current == NODES[0]
    seen = []
    for _ in range(7):
        wait = nodes.failed()
        seen.append((nodes.current[7], wait))
    # b and c at once, then the backoff before a again; the rounds go on in order
    assert seen == [
        ("b", False),
        ("c", False),
        ("a", True),
        ("b", False),
        ("c", False),
        ("a", True),
        ("b", False),
    ]


def test_a_connect_starts_a_new_round_from_where_it_is() -> None:
    nodes = BrokerUrls(NODES)
    nodes.failed()  # a died: b
    nodes.connected()
    assert nodes.current == NODES[1]
    assert nodes.failed() is False and nodes.current == NODES[2]
    assert nodes.failed() is False and nodes.current == NODES[0]
    assert nodes.failed() is True and nodes.current == NODES[1]


def test_random_order_tries_every_node_once_a_round() -> None:
    for seed in range(20):
        nodes = BrokerUrls(NODES, shuffled=True, seed=seed)
        first = nodes.current
        tried = [first]
        waits = []
        for _ in range(3):
            waits.append(nodes.failed())
            tried.append(nodes.current)
        assert set(tried[:3]) == set(NODES), seed  # a round visits each node
        assert waits == [False, False, True], seed
        assert tried[3] != tried[2]  # never the node that just failed
