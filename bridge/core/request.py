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
