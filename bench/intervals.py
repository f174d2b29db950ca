"""Bus transactions and bus time per hour of a mapping polled at four intervals (issue 35).

Run: ``.venv/bin/python bench/intervals.py [MAPPING]`` (default: bench/intervals_mapping.yaml,
32 entities at 2 s, 10 s, 60 s and 600 s, neighbours of different intervals on adjacent
registers).

Pure computation over one hour of schedule, no bus and no wall clock: the bridge's own
schedule (bridge/core/schedule.py) runs on a fake clock, each pass taking the wire time of
its plan (bridge/core/timing.py, Modbus RTU 8N1, turnaround 0), three ways:

* one read per entity: every entity read on its own at its own interval, as Home
  Assistant's modbus integration polls (``planner.one_read_per_entity``);
* each interval alone: the bridge's planner, each interval planned and polled apart (what
  two schedules that never meet would cost);
* bridge: the intervals due together planned as one set (``DeviceState.plan``), ticks
  aligned on one origin, values read along in a hole decoded too.
"""

from __future__ import annotations

import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from bridge.core.device_state import DeviceState
from bridge.core.mapping import Mapping, load_mapping
from bridge.core.planner import cost_of, one_read_per_entity, plan_reads
from bridge.core.schedule import ONCE, Schedule
from bridge.core.timing import LinkTiming

HOUR = 3600.0
DEFAULT = Path(__file__).parent / "intervals_mapping.yaml"


@dataclass(frozen=True)
class Hour:
    transactions: int
    seconds: float
    along: int = 0  # values decoded though not due (read in a hole)


def per_entity(state: DeviceState, timing: LinkTiming) -> Hour:
    """One read per entity at its own interval."""
    limits, count, seconds = state.limits(), 0, 0.0
    for key, point in state.points.items():
        passes = 1 if state.intervals[key] == ONCE else int(HOUR / state.intervals[key])
        reads = one_read_per_entity([point], limits)
        count += passes * len(reads)
        seconds += passes * cost_of(reads, timing)
    return Hour(count, seconds)


def apart(state: DeviceState, timing: LinkTiming) -> Hour:
    """The planner's reads, each interval planned and polled on its own."""
    count, seconds = 0, 0.0
    for interval in set(state.intervals.values()):
        members = [p for k, p in state.points.items() if state.intervals[k] == interval]
        reads = plan_reads(members, state.limits()).reads
        passes = 1 if interval == ONCE else int(HOUR / interval)
        count += passes * len(reads)
        seconds += passes * cost_of(reads, timing)
    return Hour(count, seconds)


def bridge(state: DeviceState, timing: LinkTiming) -> tuple[Hour, Counter[frozenset[float]]]:
    """The bridge's schedule over an hour on a fake clock; and how often each set of
    intervals came due together."""
    now, count, seconds, along = 0.0, 0, 0.0, 0
    schedule = Schedule.of(set(state.intervals.values()), now)
    sets: Counter[frozenset[float]] = Counter()
    while now < HOUR:
        due = schedule.due(now)
        plan = state.plan(due)
        sets[due - {ONCE}] += 1
        along += sum(1 for k in state.keys_of(due) if state.intervals[k] not in due)
        cost = cost_of(plan, timing)
        count, seconds, now = count + len(plan), seconds + cost, now + cost
        schedule.served(due, now)
        now = max(now, schedule.wake())
    return Hour(count, seconds, along), sets


def report(mapping: Mapping, baud: int) -> None:
    timing = LinkTiming.for_serial(baud, "N", 1, 8)
    state = DeviceState(mapping, {}, timing=timing, recheck=HOUR)
    shown = Counter(f"{v:g} s" for v in state.intervals.values())
    print(f"{mapping.model}: {len(state.points)} entities ({dict(shown)}), RTU {baud} 8N1")
    ours, sets = bridge(state, timing)
    rows = [("one read per entity", per_entity(state, timing))]
    rows += [("each interval alone", apart(state, timing)), ("bridge", ours)]
    print("| plan | transactions/h | bus s/h | bus time | values read along/h |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for name, hour in rows:
        share = f"{100 * hour.seconds / HOUR:.2f} %"
        print(f"| {name} | {hour.transactions} | {hour.seconds:.1f} | {share} | {hour.along} |")
    base = rows[0][1]
    print(
        f"bridge / one read per entity: {ours.transactions / base.transactions:.2f} of the "
        f"transactions, {ours.seconds / base.seconds:.2f} of the bus time"
    )
    together = {"+".join(f"{i:g}" for i in sorted(k)): n for k, n in sorted(sets.items(), key=len)}
    print(f"passes by intervals due together: {together}\n")


def main() -> None:
    path = Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT
    mapping = load_mapping(path)
    for baud in (9600, 38400):
        report(mapping, baud)


if __name__ == "__main__":
    main()
