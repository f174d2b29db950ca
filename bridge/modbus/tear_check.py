"""The poller's side of tear-free 32-bit values (bridge/core/tearing.py): after a pass,
each two-register number read in two reads is checked with one-register reads ahead of
the polls; a value whose high word kept moving, or whose check failed, is not published
from this pass (it keeps its last value and is read again next poll)."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import TYPE_CHECKING

from bridge.core.entity import Table
from bridge.core.request import Read
from bridge.core.tearing import Torn, torn_values, untear
from bridge.errors import ModbusError
from bridge.modbus.scheduler import Priority

if TYPE_CHECKING:
    from bridge.modbus.poller import DevicePoller

log = logging.getLogger(__name__)
Address = tuple[Table, int]


async def check_torn(
    poller: DevicePoller, keys: Sequence[str], reads: Sequence[Read], fresh: set[Address]
) -> None:
    """Check the torn values among ``keys`` that this pass read (both words in ``fresh``)."""
    points = [poller.points[k] for k in keys]
    for torn in torn_values(points, reads):
        cells = {(torn.table, torn.high), (torn.table, torn.low)}
        if not cells <= fresh:
            continue
        words = await _checked(poller, torn)
        if words is None:
            fresh -= cells  # not published from this pass
            continue
        poller.image[(torn.table, torn.high)], poller.image[(torn.table, torn.low)] = words


async def _checked(poller: DevicePoller, torn: Torn) -> tuple[int, int] | None:
    image = poller.image
    check = untear(torn, image[(torn.table, torn.high)], image[(torn.table, torn.low)])
    try:
        read = next(check)
        while True:
            (word,) = await poller.submit(read, Priority.READ_NOW)
            read = check.send(word)
    except StopIteration as done:
        words: tuple[int, int] | None = done.value
    except ModbusError as exc:
        log.debug("%s: %s not checked: %s", poller.device.id, torn.point.key, exc)
        return None
    if words is None:
        log.debug("%s: %s kept moving; read again next poll", poller.device.id, torn.point.key)
    return words
