"""The edge's side of tear-free 32-bit values (bridge/core/tearing.py): after a pass,
each two-register number read in two reads is checked with one-register reads ahead of
the polls; a value whose high word kept moving, or whose check failed, is not decoded
from this pass (it keeps its last value and is read again next poll)."""

from __future__ import annotations

import logging
from collections.abc import Sequence

from bridge.core.device_state import DeviceState
from bridge.core.planner import Address
from bridge.core.request import Read
from bridge.core.tearing import Torn, torn_values, untear
from bridge.errors import ModbusError
from bridge.modbus.device_link import DeviceLink
from bridge.modbus.scheduler import Priority

log = logging.getLogger(__name__)


async def check_torn(
    state: DeviceState,
    link: DeviceLink,
    keys: Sequence[str],
    reads: Sequence[Read],
    fresh: set[Address],
) -> None:
    """Check the torn values among ``keys`` that this pass read (both words in ``fresh``)."""
    points = [state.points[k] for k in keys]
    for torn in torn_values(points, reads):
        cells = {(torn.table, torn.high), (torn.table, torn.low)}
        if not cells <= fresh:
            continue
        words = await _checked(state, link, torn)
        if words is None:
            fresh -= cells  # not decoded from this pass
            continue
        state.image[(torn.table, torn.high)], state.image[(torn.table, torn.low)] = words


async def _checked(state: DeviceState, link: DeviceLink, torn: Torn) -> tuple[int, int] | None:
    image = state.image
    check = untear(torn, image[(torn.table, torn.high)], image[(torn.table, torn.low)])
    device_id = link.device.id
    try:
        read = next(check)
        while True:
            (word,) = await link.submit(read, Priority.READ_NOW)
            read = check.send(word)
    except StopIteration as done:
        words: tuple[int, int] | None = done.value
    except ModbusError as exc:
        log.debug("%s: %s not checked: %s", device_id, torn.point.key, exc)
        return None
    if words is None:
        log.debug("%s: %s kept moving; read again next poll", device_id, torn.point.key)
    return words
