"""The soak's invariants: pure functions over what the soak recorded, each returning the
``Violation``s it finds (empty when the bridge behaved).

The driver (bench/soak_faults.py) records events as they happen (commands it sent and
when the observer saw them arrive, the simulator's write log, every value and
availability the bridge published, health reports, log lines, process samples) and runs
these checkers over the records every few seconds, so a violation is found while the
run goes on, not only at its end. Times are ``time.monotonic()`` seconds.

* ``check_commands``: a command is written at most once, never later than its expiry
  after it arrived, and never at all when it was retained; a write nobody sent is one too.
* ``check_guarded``: no write to a register the mapping guards (``dangerous``).
* ``check_counters``: a ``total_increasing`` value never falls unless the bridge confirmed
  a reset (its health ``counter_resets`` grew to cover it within ``confirm_within``).
* ``check_values``: a value published (changed) equals what the simulator held for that
  key at some moment of the preceding poll period (plus a grace for the read's travel).
* ``check_availability``: a device silent for longer than its offline threshold is not
  shown online.
* ``check_log_rate``: at most ``limit`` WARNING-or-worse lines a minute.
* ``check_bounded``: RSS and file descriptors stay within a margin of where they settled.
"""

from __future__ import annotations

import bisect
import math
import statistics
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

LATE_SLACK = 0.5  # s: a write's own scheduling and the two processes' loops
VALUE_GRACE = 3.0  # s: a poll's read, decode and publish after the register held the value


@dataclass(frozen=True, slots=True)
class Violation:
    invariant: str
    at: float
    detail: str


@dataclass(frozen=True, slots=True)
class Sent:
    """A command the driver published: ``word`` is what its write puts at ``address``."""

    ident: int
    at: float
    device: str
    unit: int
    address: int
    word: int
    retained: bool
    expiry: float  # the command's lifetime: the earlier of command_expiry and MQTT 5 expiry
    arrived: float | None = None  # when the observer (a subscriber like the bridge) got it


@dataclass(frozen=True, slots=True)
class Written:
    at: float
    unit: int
    address: int
    values: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class Published:
    at: float
    device: str
    key: str
    value: object


@dataclass(frozen=True, slots=True)
class Availability:
    at: float
    device: str
    online: bool


@dataclass(frozen=True, slots=True)
class Resets:
    """A health report's ``counter_resets`` of a device."""

    at: float
    device: str
    count: int


@dataclass(frozen=True, slots=True)
class Silence:
    device: str
    start: float
    end: float  # math.inf while it lasts


@dataclass(frozen=True, slots=True)
class Sample:
    at: float
    rss_kib: int
    fds: int


def check_commands(sent: Sequence[Sent], written: Sequence[Written]) -> list[Violation]:
    """Writes to a command register, matched to the latest command of that word sent
    before it (each command has its own word)."""
    registers = {(s.unit, s.address) for s in sent}
    by_word: dict[tuple[int, int, int], list[Sent]] = defaultdict(list)
    for command in sorted(sent, key=lambda s: s.at):
        by_word[(command.unit, command.address, command.word)].append(command)
    done: set[int] = set()
    found = []
    for write in written:
        if (write.unit, write.address) not in registers:
            continue
        candidates = [
            s
            for s in by_word.get((write.unit, write.address, write.values[0]), [])
            if s.at <= write.at
        ]
        if not candidates:
            detail = (
                f"unit {write.unit} address {write.address} = {write.values}: no command sent it"
            )
            found.append(Violation("command unexplained", write.at, detail))
            continue
        command = candidates[-1]
        name = f"command {command.ident} ({command.device} = {command.word})"
        if command.retained:
            found.append(Violation("retained command executed", write.at, name))
        if command.ident in done:
            found.append(Violation("command executed twice", write.at, name))
        done.add(command.ident)
        start = command.arrived if command.arrived is not None else command.at
        late = write.at - start - command.expiry
        if late > LATE_SLACK:
            found.append(Violation("command executed late", write.at, f"{name}: {late:.2f} s late"))
    return found


def check_guarded(
    written: Sequence[Written], guarded: Mapping[tuple[int, int], str]
) -> list[Violation]:
    """``guarded``: (unit, wire address) -> the entity it belongs to."""
    return [
        Violation("guarded write", w.at, f"unit {w.unit} {guarded[(w.unit, a)]} (address {a})")
        for w in written
        for a in range(w.address, w.address + len(w.values))
        if (w.unit, a) in guarded
    ]


def check_counters(
    published: Sequence[Published], resets: Sequence[Resets], until: float, confirm_within: float
) -> list[Violation]:
    """``published``: the total_increasing values in arrival order. The n-th fall of a
    device's counters must be covered by a health report, no later than
    ``confirm_within`` after it, saying ``counter_resets >= n``; a fall younger than that
    at ``until`` is not judged yet."""
    last: dict[tuple[str, str], float] = {}
    falls: dict[str, list[tuple[float, str]]] = defaultdict(list)
    for p in published:
        if not isinstance(p.value, int | float) or isinstance(p.value, bool):
            continue
        before = last.get((p.device, p.key))
        if before is not None and p.value < before:
            falls[p.device].append((p.at, f"{p.device}.{p.key} fell {before} -> {p.value}"))
        last[(p.device, p.key)] = p.value
    found = []
    for device, device_falls in falls.items():
        reports = [r for r in resets if r.device == device]
        for n, (at, detail) in enumerate(device_falls, start=1):
            if at + confirm_within > until:
                continue
            if not any(at <= r.at <= at + confirm_within and r.count >= n for r in reports):
                found.append(Violation("counter fell without a confirmed reset", at, detail))
    return found


def check_values(
    published: Sequence[Published],
    history: Mapping[tuple[str, str], Sequence[tuple[float, object]]],
    windows: Mapping[tuple[str, str], float],
    held_up: Sequence[tuple[float, float]] = (),
) -> list[Violation]:
    """Each published value of a watched key that differs from the one published before
    it must equal a value the simulator held within ``window`` (+ grace) before it came.
    ``history[(device, key)]``: (since when, value) in time order. ``held_up``: the
    (start, end) of broker outages and stalls: a message that arrived during one or just
    after it may have been published at its start (the broker held it, not the bridge).
    ``None`` (not read yet, e.g. a fresh start's first document) is no value: skipped."""
    last: dict[tuple[str, str], object] = {}
    times = {name: [t for t, _ in changes] for name, changes in history.items()}
    found = []
    for p in published:
        name = (p.device, p.key)
        if name not in history or name not in windows or p.value is None:
            continue
        if name in last and last[name] == p.value:
            continue
        last[name] = p.value
        since = min([s for s, e in held_up if s <= p.at <= e + VALUE_GRACE] + [p.at])
        start = since - windows[name] - VALUE_GRACE
        held = _held_between(times[name], history[name], start, p.at + 0.5)
        if not any(_same(p.value, v) for v in held):
            shown = ", ".join(repr(v) for v in held[-4:])
            detail = f"{p.device}.{p.key} = {p.value!r}; the device held {shown}"
            found.append(Violation("value not the device's", p.at, detail))
    return found


def _held_between(
    times: Sequence[float], history: Sequence[tuple[float, object]], start: float, end: float
) -> list[object]:
    first = max(0, bisect.bisect_right(times, start) - 1)  # the value in effect at start
    last = bisect.bisect_right(times, end)
    return [v for _, v in history[first:last]]


def _same(a: object, b: object) -> bool:
    if isinstance(a, int | float) and isinstance(b, int | float):
        return math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-9)
    return a == b


def check_availability(
    availability: Sequence[Availability],
    silences: Sequence[Silence],
    thresholds: Mapping[str, float],
    until: float,
) -> list[Violation]:
    """While a device is silent, from its threshold on, it must not be shown online: not
    by the availability in effect then, nor by one published later in the silence."""
    found = []
    for silence in silences:
        due = silence.start + thresholds[silence.device]
        if due >= min(silence.end, until):
            continue
        events = [a for a in availability if a.device == silence.device]
        before = [a for a in events if a.at <= due]
        if before and before[-1].online:
            late = due - silence.start
            detail = f"{silence.device} silent since {silence.start:.0f}, online at +{late:.0f} s"
            found.append(Violation("online while silent", due, detail))
        for a in events:
            if due < a.at < min(silence.end, until) and a.online:
                found.append(
                    Violation("online while silent", a.at, f"{silence.device} said online")
                )
    return found


def check_log_rate(warnings: Sequence[float], limit: int) -> list[Violation]:
    """``warnings``: the times of WARNING-or-worse lines; more than ``limit`` in any minute
    (counted from the first line of each burst) is a storm."""
    found = []
    times = sorted(warnings)
    start = 0
    for end, at in enumerate(times):
        while times[start] < at - 60:
            start += 1
        if end - start + 1 == limit + 1:  # once per storm, where it crossed the limit
            found.append(Violation("warning storm", at, f"{limit + 1} warnings within a minute"))
    return found


def slope_per_hour(points: Sequence[tuple[float, float]]) -> float:
    """Least squares slope of (seconds, value), per hour (0 with fewer than 3 points)."""
    if len(points) < 3:
        return 0.0
    xs, ys = zip(*points, strict=True)
    if len(set(xs)) < 2:
        return 0.0
    return 3600 * statistics.linear_regression(xs, ys).slope


def check_bounded(
    samples: Sequence[Sample], rss_margin_kib: int, fd_margin: int
) -> list[Violation]:
    """After the first fifth of the run (start-up, caches filling), RSS and open file
    descriptors stay within a margin of the median of that fifth's last half."""
    if len(samples) < 10:
        return []
    settle = samples[len(samples) // 10 : len(samples) // 5 + 1]
    rss = statistics.median(s.rss_kib for s in settle)
    fds = statistics.median(s.fds for s in settle)
    rss_over = [s for s in samples[len(samples) // 5 :] if s.rss_kib > rss + rss_margin_kib]
    fds_over = [s for s in samples[len(samples) // 5 :] if s.fds > fds + fd_margin]
    found = []  # the first crossing of each: once past its bound, a resource stays so
    if rss_over:
        s = rss_over[0]
        found.append(
            Violation(
                "RSS unbounded", s.at, f"{s.rss_kib / 1024:.1f} MiB, settled at {rss / 1024:.1f}"
            )
        )
    if fds_over:
        s = fds_over[0]
        found.append(Violation("fds unbounded", s.at, f"{s.fds} open, settled at {fds:.0f}"))
    return found
