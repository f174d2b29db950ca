"""The transactions the core asks the Modbus edge to perform: value objects, no I/O."""

from __future__ import annotations

from dataclasses import dataclass

from bridge.core.entity import Table


@dataclass(frozen=True, slots=True)
class Read:
    """Read ``count`` registers (or bits) of ``table`` starting at wire ``address``."""

    table: Table
    address: int
    count: int

    @property
    def function(self) -> int:
        return self.table.read_function

    @property
    def span(self) -> range:
        return range(self.address, self.address + self.count)


def split_read(read: Read, limit: int) -> tuple[Read, ...]:
    """``read`` as consecutive reads of at most ``limit`` registers (or bits) each."""
    if limit < 1:
        raise ValueError(f"a read limit is at least 1, not {limit}")
    return tuple(
        Read(read.table, first, min(limit, read.address + read.count - first))
        for first in range(read.address, read.address + read.count, limit)
    )


@dataclass(frozen=True, slots=True)
class Write:
    """One write transaction: function code, table, first wire address and the raw values.

    For FC05 the single value is the 16-bit word sent (0xFF00 standard, 0x00FF on devices
    that print it so, 0x0000 for OFF); for FC15 the values are bits (0/1).
    """

    function: int
    table: Table
    address: int
    values: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class WriteSequence:
    """Writes that make one command (a sign and a magnitude, a pulse's edges, the keys of a
    multi-key /set): sent back to back, never left half done.

    ``undo[i]`` puts back what ``writes[i]`` changed (None: nothing to put back); when a
    later write fails, the writes already done are undone in reverse order.
    """

    writes: tuple[Write, ...]
    undo: tuple[Write | None, ...]

    def __post_init__(self) -> None:
        if not self.writes or len(self.undo) != len(self.writes):
            raise ValueError("a write sequence has one undo (or None) per write, at least one")
