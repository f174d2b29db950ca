"""Addresses as printed in a manual, and the per-mapping rule that turns them into wire addresses.

Three printed forms are accepted:

* an integer (YAML ``0x98`` or ``152``), sent as ``printed + offset``
  (Nastec index 0x98 -> wire 0x97 with ``offset: -1``; Vacon ID 2001 -> 2000);
* a string of digits, ``0x`` hex or hex with an ``H`` suffix (``"1F00H"``), same rule;
* a parameter code ``<group letter><group number>.<index>`` (P2 ``F3.01`` -> 0xF301):
  the high byte is the group's base plus the group number, the low byte the index in binary.
"""

from __future__ import annotations

import re

from pydantic import BaseModel, ConfigDict, Field

PrintedAddress = int | str

_PARAMETER = re.compile(r"^([A-Za-z])(\d{1,2})\.(\d{1,3})$")
_HEX_SUFFIX = re.compile(r"^([0-9A-Fa-f]+)[Hh]$")


class Addressing(BaseModel):
    """How the manual prints addresses and how they become wire addresses."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    offset: int = Field(0, description="wire = printed + offset, for numeric addresses")
    groups: dict[str, int] = Field(
        default_factory=dict,
        description="parameter-code groups: letter -> high byte of group 0 (P2: F -> 0xF0)",
    )
    display: str = Field("hex", pattern="^(hex|dec)$", description="how to print addresses")


def to_wire(printed: PrintedAddress, rule: Addressing) -> int:
    """Return the wire address of ``printed`` under ``rule``; raise ValueError if impossible."""
    if isinstance(printed, bool):
        raise ValueError("an address cannot be a boolean")
    if isinstance(printed, int):
        wire = printed + rule.offset
    else:
        wire = _parse_string(printed.strip(), rule)
    if not 0 <= wire <= 0xFFFF:
        raise ValueError(f"address {printed!r} gives wire address {wire}, outside 0..65535")
    return wire


def _parse_string(text: str, rule: Addressing) -> int:
    if match := _PARAMETER.match(text):
        letter, group, index = match.group(1), int(match.group(2)), int(match.group(3))
        if letter not in rule.groups:
            known = ", ".join(sorted(rule.groups)) or "none declared"
            raise ValueError(f"parameter group {letter!r} of {text!r} unknown ({known})")
        high = rule.groups[letter] + group
        if high > 0xFF or index > 0xFF:
            raise ValueError(f"parameter code {text!r} does not fit in 16 bits")
        return (high << 8) | index
    if match := _HEX_SUFFIX.match(text):
        return int(match.group(1), 16) + rule.offset
    try:
        return int(text, 0) + rule.offset
    except ValueError:
        raise ValueError(
            f"address {text!r} is not a number, 0x-hex, NNNNH hex or a parameter code like F3.01"
        ) from None


def format_address(printed: PrintedAddress, rule: Addressing) -> str:
    """Render a printed address the way the mapping's manual prints it."""
    if isinstance(printed, str):
        return printed
    return f"0x{printed:04X}" if rule.display == "hex" else str(printed)
