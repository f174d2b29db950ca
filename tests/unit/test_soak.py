"""The soak's pure parts (bench/soak_schedule.py, bench/soak_invariants.py): the schedule is
seeded and repeatable, and each checker catches a violation planted in recorded events
(and passes the same events without it). Nothing runs or is timed here: ``make soak`` does.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

from soak_invariants import (
    Availability,
    Published,
    Resets,
    Sample,
    Sent,
    Silence,
    Written,
    check_availability,
    check_bounded,
    check_commands,
    check_counters,
    check_guarded,
    check_log_rate,
    check_values,
    slope_per_hour,
)
from soak_schedule import KINDS, PER_HOUR, WARM_UP, build_schedule, parse_duration, summary

# --- the schedule --------------------------------------------------------------------------


def test_the_same_seed_throws_the_same_faults() -> None:
    assert build_schedule(7, 3600) == build_schedule(7, 3600)
    assert build_schedule(7, 3600) != build_schedule(8, 3600)


def test_an_hour_is_a_month_of_faults_and_five_minutes_throw_every_kind() -> None:
    assert summary(build_schedule(1, 3600)) == PER_HOUR
    short = build_schedule(1, 300)
    assert set(summary(short)) == set(KINDS)
    assert all(count >= 1 for count in summary(short).values())


@pytest.mark.parametrize("seconds", [300, 3600])
def test_faults_come_in_order_after_the_warm_up_and_end_within_the_run(seconds: float) -> None:
    schedule = build_schedule(3, seconds)
    assert [f.at for f in schedule] == sorted(f.at for f in schedule)
    assert [f.position for f in schedule] == list(range(len(schedule)))
    assert all(f.at >= WARM_UP and f.at + f.hold <= seconds for f in schedule)


def test_durations() -> None:
    assert parse_duration("5m") == 300
    assert parse_duration("1h") == 3600
    assert parse_duration("90") == 90
    for wrong in ("soon", "10s", "1d"):
        with pytest.raises(ValueError, match="duration"):
            parse_duration(wrong)


# --- commands and guarded writes ----------------------------------------------------------


def sent(ident: int, word: int, at: float = 0.0, *, retained: bool = False) -> Sent:
    return Sent(ident, at, "vacon", 5, 2003, word, retained, expiry=3.0, arrived=at + 0.01)


def test_a_command_executed_once_and_in_time_passes() -> None:
    commands = [sent(1, 1000), sent(2, 1001, at=1.0)]
    written = [Written(0.2, 5, 2003, (1000,)), Written(1.3, 5, 2003, (1001,))]
    assert check_commands(commands, written) == []


def test_a_command_executed_twice_is_caught() -> None:
    written = [Written(0.2, 5, 2003, (1000,)), Written(0.9, 5, 2003, (1000,))]
    (found,) = check_commands([sent(1, 1000)], written)
    assert (found.invariant, found.at) == ("command executed twice", 0.9)


def test_a_retained_late_or_unsent_command_is_caught() -> None:
    commands = [sent(1, 1000, retained=True), sent(2, 1001)]
    written = [
        Written(0.1, 5, 2003, (1000,)),
        Written(4.0, 5, 2003, (1001,)),  # 3.99 s after it arrived, expiry 3 s
        Written(5.0, 5, 2003, (4242,)),  # nobody sent 4242
        Written(5.0, 5, 9999, (4242,)),  # not a command register: not judged here
    ]
    found = [v.invariant for v in check_commands(commands, written)]
    assert found == ["retained command executed", "command executed late", "command unexplained"]


def test_a_write_to_a_guarded_register_is_caught() -> None:
    guarded = {(5, 2000): "reverse"}
    assert check_guarded([Written(1.0, 5, 2003, (1,))], guarded) == []
    (found,) = check_guarded([Written(1.0, 5, 1999, (0, 1))], guarded)
    assert found.invariant == "guarded write" and "reverse" in found.detail


# --- counters, values, availability --------------------------------------------------------


def test_a_counter_that_falls_is_caught_unless_the_bridge_confirmed_a_reset() -> None:
    readings = [Published(t, "meter", "energy", v) for t, v in ((1, 10.0), (2, 11.0), (3, 0.5))]
    (found,) = check_counters(readings, [], until=100, confirm_within=25)
    assert found.invariant == "counter fell without a confirmed reset" and found.at == 3
    confirmed = [Resets(10, "meter", 1)]
    assert check_counters(readings, confirmed, until=100, confirm_within=25) == []
    assert check_counters(readings, [], until=20, confirm_within=25) == []  # not judged yet


def test_a_value_the_device_did_not_hold_within_a_poll_is_caught() -> None:
    history = {("meter", "power"): [(0.0, 100.0), (10.0, 200.0), (20.0, 300.0)]}
    windows = {("meter", "power"): 2.0}
    fine = [Published(11.0, "meter", "power", 100.0), Published(21.0, "meter", "power", 300.0)]
    assert check_values(fine, history, windows) == []
    stale = [Published(19.0, "meter", "power", 100.0)]  # 9 s after the device moved on
    (found,) = check_values(stale, history, windows)
    assert found.invariant == "value not the device's"
    # a broker stall from 12 s to 18 s held the message: the bridge may have sent it at 12
    assert check_values(stale, history, windows, held_up=[(12.0, 18.0)]) == []
    assert check_values([Published(19.0, "meter", "power", None)], history, windows) == []


def test_a_device_shown_online_while_silent_beyond_its_threshold_is_caught() -> None:
    silence = [Silence("pump", 100.0, 200.0)]
    went_offline = [Availability(1, "pump", True), Availability(110, "pump", False)]
    assert check_availability(went_offline, silence, {"pump": 20.0}, until=300) == []
    stayed = [Availability(1, "pump", True)]
    (found,) = check_availability(stayed, silence, {"pump": 20.0}, until=300)
    assert (found.invariant, found.at) == ("online while silent", 120.0)
    flapped = [*went_offline, Availability(150, "pump", True)]
    assert [v.at for v in check_availability(flapped, silence, {"pump": 20.0}, until=300)] == [150]
    lasting = [Silence("pump", 100.0, math.inf)]
    assert check_availability(stayed, lasting, {"pump": 20.0}, until=110) == []  # not yet due


# --- the log and the process ---------------------------------------------------------------


def test_a_warning_storm_is_caught_once() -> None:
    assert check_log_rate([float(t) for t in range(0, 600, 5)], limit=30) == []
    storm = [100 + t / 10 for t in range(100)]
    (found,) = check_log_rate(storm, limit=30)
    assert found.invariant == "warning storm"


def test_rss_and_file_descriptors_bounded_and_their_slopes() -> None:
    flat = [Sample(t * 60.0, 60_000, 15) for t in range(60)]
    assert check_bounded(flat, rss_margin_kib=65_536, fd_margin=64) == []
    assert slope_per_hour([(s.at, s.rss_kib) for s in flat]) == 0
    leaking = [Sample(t * 60.0, 60_000 + 2_000 * t, 15 + 2 * t) for t in range(60)]
    found = {v.invariant for v in check_bounded(leaking, rss_margin_kib=65_536, fd_margin=64)}
    assert found == {"RSS unbounded", "fds unbounded"}
    assert slope_per_hour([(s.at, s.fds) for s in leaking]) == pytest.approx(120)
