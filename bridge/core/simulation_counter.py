"""What a simulated counter reads when it misbehaves the way real ones do. Pure.

Each fault is what a real device has been seen to do to a ``total_increasing`` counter,
the readings that put phantom energy in Home Assistant's statistics
(bridge/core/counters.py is what stops them):

- ``zero``: the next read answers 0 (a gateway reconnecting, a module not ready);
- ``reboot``: the next ``REBOOT_READS`` reads answer 0, then the count again (a power
  cycle of a controller that reads its counters back from memory a moment after start);
- ``tear``: the next read answers the high word with the low word already rolled over
  to 0 (a 32-bit counter the device updates one word at a time: 19999 read as 10000);
- ``jitter``: the next read answers one least significant digit less;
- ``wrap``: the counter jumps two digits below its width and rolls over on its own;
- ``reset``: the counter is cleared for good (a meter replaced, a reset at the panel).

``fault_reads`` gives the answers the next reads get instead of the image (one dict of
cells per read), ``fault_image`` what the fault changes in the image for good.
"""

from __future__ import annotations

from enum import StrEnum

from bridge.core.codec import Image, decode
from bridge.core.counters import counter_width, is_counter
from bridge.core.entity import Order, Table
from bridge.core.mapping import Point
from bridge.core.simulation import words_for
from bridge.errors import ValueRejectedError

Cell = tuple[Table, int]
REBOOT_READS = 2  # fewer than the bridge's default confirmation (counters.CONFIRM)


class CounterFault(StrEnum):
    """The ways a simulated counter can misread (see the module docstring)."""

    ZERO = "zero"
    REBOOT = "reboot"
    TEAR = "tear"
    JITTER = "jitter"
    WRAP = "wrap"
    RESET = "reset"


def counter_fault(name: str) -> CounterFault:
    """The fault called ``name`` (ValueRejectedError naming the faults there are)."""
    try:
        return CounterFault(name)
    except ValueError:
        known = ", ".join(fault.value for fault in CounterFault)
        raise ValueRejectedError(f"counter fault {name!r:.40}: one of {known}") from None


def check_counter(point: Point) -> None:
    """ValueRejectedError unless ``point`` is a counter (state class total or
    total_increasing)."""
    if not is_counter(point):
        raise ValueRejectedError(f"{point.key} is not a counter (state class total*)")


def fault_reads(point: Point, fault: CounterFault, image: Image) -> tuple[dict[Cell, int], ...]:
    """The answers the next reads of ``point`` get instead of the image (empty: none)."""
    value = _number(point, image)
    lsb = abs(point.entity.scale)
    if fault is CounterFault.ZERO:
        return (words_for(point, 0, image),)
    if fault is CounterFault.REBOOT:
        return (words_for(point, 0, image),) * REBOOT_READS
    if fault is CounterFault.JITTER:
        return (words_for(point, max(value - lsb, 0), image),) if value >= lsb else ()
    if fault is CounterFault.TEAR:
        return (_torn(point, image),)
    return ()


def fault_image(point: Point, fault: CounterFault, image: Image) -> dict[Cell, int]:
    """What ``fault`` changes in the image for good (empty for a misread)."""
    if fault is CounterFault.RESET:
        return words_for(point, 0, image)
    if fault is CounterFault.WRAP:
        width = counter_width(point)
        if width is None:
            raise ValueRejectedError(f"{point.key} is a {point.entity.data_type}: it never wraps")
        return words_for(point, (width - 2) * abs(point.entity.scale), image)
    return {}


def _torn(point: Point, image: Image) -> dict[Cell, int]:
    """The words with the low one rolled over to 0 and the high one not yet counted."""
    if point.count != 2:
        raise ValueRejectedError(f"{point.key} is one register: it cannot tear")
    cells = words_for(point, _number(point, image), image)
    low = min(cells) if point.entity.word_order is Order.LITTLE else max(cells)
    return cells | {low: 0}


def _number(point: Point, image: Image) -> float:
    value = decode(point, image)
    if not isinstance(value, int | float) or isinstance(value, bool):
        raise ValueRejectedError(f"{point.key} reads {value!r}, not a number")
    return float(value)
