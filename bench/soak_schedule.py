"""The soak's fault schedule: a month of a site's faults, squeezed into the soak's duration.

Pure: ``build_schedule(seed, seconds)`` returns the same faults for the same seed and
duration (``random.Random(seed)``, nothing else), so a violation found at schedule
position N is found again by running the same seed. ``PER_HOUR`` is how often each kind
comes in one hour of soak, which stands for one month of a site: a broker restarted now
and then, a daily config reload, a few device reboots, noise on the line every few days,
masters coming and going, bursts of commands. Each kind comes at least once, so the
5-minute CI form throws every kind too. Times are spread uniformly over the run after a
warm-up (the bridge has to be up and polling before the first fault means anything).
"""

from __future__ import annotations

import random
import re
from dataclasses import dataclass

# one hour of soak = one month on site: how often each kind comes in that hour
PER_HOUR: dict[str, int] = {
    "broker_restart": 4,  # broker (or its node) restarted
    "broker_stall": 3,  # the broker stops acknowledging (SIGSTOP) for a while
    "device_reboot": 6,  # counters read 0, then come back (simulator counter_fault reboot/zero)
    "counter_reset": 1,  # a meter really reset to 0 (the bridge must confirm it)
    "device_silent": 4,  # a bus cable pulled: the device answers nothing for minutes
    "line_noise": 8,  # CRC errors on the RS-485 line for a while
    "torn_frames": 8,  # replies torn in two (a slow converter) for a while
    "config_reload": 30,  # SIGHUP, config file rewritten (daily)
    "mapping_reload": 10,  # bridge/request/mapping/reload
    "gateway_masters": 20,  # masters connect, flood the gateway, vanish
    "ha_online": 8,  # Home Assistant restarted: `online` on homeassistant/status
    "command_burst": 60,  # bursts of commands, some retained, some with a short expiry
}
KINDS = tuple(PER_HOUR)
WARM_UP = 30.0  # seconds before the first fault
TARGETS = {  # which device (or what) a kind picks its target from
    "device_reboot": ("genset", "meter", "pump"),
    "counter_reset": ("meter",),
    "device_silent": ("pump", "softstarter", "meter", "genset"),
}
_DURATION = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*([smh]?)\s*$")


@dataclass(frozen=True, slots=True)
class Fault:
    """One fault: when (seconds after the start), what, on what, for how long (seconds;
    0 for instant faults), and a seed of its own for its details (values, noise)."""

    position: int
    at: float
    kind: str
    target: str
    hold: float
    seed: int


def parse_duration(text: str) -> float:
    """``5m``, ``1h``, ``90s`` or plain seconds -> seconds; ValueError otherwise."""
    match = _DURATION.match(text)
    if match is None:
        raise ValueError(f"duration {text!r}: say 90s, 5m or 1h")
    number, unit = float(match.group(1)), match.group(2) or "s"
    seconds = number * {"s": 1, "m": 60, "h": 3600}[unit]
    if seconds <= WARM_UP:
        raise ValueError(f"duration {text!r}: longer than the {WARM_UP:g} s warm-up, please")
    return seconds


def count_for(kind: str, seconds: float) -> int:
    """How many faults of ``kind`` a run of ``seconds`` gets (at least one)."""
    return max(1, round(PER_HOUR[kind] * seconds / 3600))


def build_schedule(seed: int, seconds: float) -> tuple[Fault, ...]:
    """Every fault of a run of ``seconds``, in time order; the same for the same seed."""
    rng = random.Random(seed)  # noqa: S311 - a repeatable schedule, not a secret
    drawn: list[tuple[float, str, str, float, int]] = []
    end = seconds - _hold_limit(seconds)  # the last fault still ends inside the run
    for kind in KINDS:
        for _ in range(count_for(kind, seconds)):
            at = rng.uniform(WARM_UP, max(WARM_UP, end))
            target = rng.choice(TARGETS.get(kind, ("",)))
            hold = _hold(kind, rng, seconds)
            drawn.append((round(at, 3), kind, target, hold, rng.randrange(2**31)))
    drawn.sort()
    return tuple(Fault(i, *item) for i, item in enumerate(drawn))


def _hold_limit(seconds: float) -> float:
    return min(120.0, seconds / 5)


def _hold(kind: str, rng: random.Random, seconds: float) -> float:
    """How long a lasting fault lasts: minutes for a silent device, seconds for the rest;
    short runs get shorter holds so every fault ends (and is checked) within the run."""
    low, high = {
        "broker_restart": (1.0, 10.0),  # down between kill and start
        "broker_stall": (5.0, 40.0),
        "device_silent": (60.0, 180.0),
        "line_noise": (10.0, 40.0),
        "torn_frames": (10.0, 40.0),
        "gateway_masters": (5.0, 30.0),
    }.get(kind, (0.0, 0.0))
    return round(min(rng.uniform(low, high), _hold_limit(seconds)), 3)


def summary(schedule: tuple[Fault, ...]) -> dict[str, int]:
    """Faults per kind, every kind listed."""
    counts = dict.fromkeys(KINDS, 0)
    for fault in schedule:
        counts[fault.kind] += 1
    return counts
