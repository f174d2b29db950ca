"""The edge's side of bracketed values (bridge/core/bracket.py): a ``scale_by`` value
read apart from its exponent gets its exponent read before its read and after it.

    since = await read_before(link, brackets, priority, fresh)  # before the pass
    ... the pass's reads ...
    await read_after(state, link, brackets, since, priority=priority, fresh=fresh)
    state.decode_fresh(keys, fresh, since)   # decodes a value only if its factor held

``read_before`` sends the dedicated reads the plan asks for ahead of the pass (its own
read of the exponent comes after a value's read) and returns the request count the pass
starts from; ``read_after`` sends one read of each exponent that no read after its values
read yet. A failed read leaves the values unchecked: they keep their value this pass.
"""

from __future__ import annotations

from collections.abc import Iterable

from bridge.core.bracket import Bracket
from bridge.core.device_state import DeviceState
from bridge.core.planner import Address
from bridge.modbus.device_link import Link
from bridge.modbus.scheduler import Priority


async def read_before(
    state: DeviceState,
    link: Link,
    brackets: Iterable[Bracket],
    priority: Priority,
    fresh: set[Address],
) -> int:
    """Read the exponents whose plan read follows a value's; return the request count
    before them (what ``decode_fresh`` judges the pass's readings from)."""
    since = state.requests
    for read in state.exponents_before(brackets):
        await link.read_block(read, priority, fresh)
    return since


async def read_after(
    state: DeviceState,
    link: Link,
    brackets: Iterable[Bracket],
    since: int,
    *,
    priority: Priority,
    fresh: set[Address],
) -> None:
    """Read each exponent that was not read after the last read of its values."""
    for read in state.unconfirmed(brackets, since):
        await link.read_block(read, priority, fresh)
