"""A simulated SunSpec device: a device image's holding registers, served as they are.

``SunSpecUnit(unit, image)`` joins a ``Simulator`` beside mapping units. It answers FC03
within the image (the ``SunS`` marker, its models, the end marker); any read that leaves
the image is refused with 02 (illegal data address) as a real device refuses it, and every
other function code with 01. The registers never change: no writes, no motion.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from pymodbus.constants import ExcCodes
from pymodbus.simulator import DataType, SimData, SimDevice

from bridge.core.simulation import Quirks
from bridge.sunspec.image import DeviceImage

_READ_HOLDING = 3
Request = tuple[int, int, int]  # unit, function code, address


@dataclass(frozen=True, slots=True)
class SunSpecUnit:
    """One SunSpec device on the simulated bus."""

    unit: int
    image: DeviceImage


@dataclass(slots=True)
class ImageDevice:
    """The served side of a ``SunSpecUnit``: pymodbus' hook over the image."""

    spec: SunSpecUnit
    requests: deque[Request] = field(default_factory=deque)
    quirks: Quirks = field(default_factory=Quirks)  # none: a SunSpec unit has no quirks

    @property
    def unit(self) -> int:
        return self.spec.unit

    def sim_device(self) -> SimDevice:
        words = [SimData(0, count=0x10000, values=0, datatype=DataType.REGISTERS)]
        bits = [SimData(0, values=[False] * 16, datatype=DataType.BITS)]
        return SimDevice(self.unit, simdata=(bits, bits, words, words), action=self.action)

    async def action(  # noqa: PLR0917 - the signature of pymodbus' SimAction
        self,
        function_code: int,
        start: int,
        address: int,
        count: int,
        registers: list[int],
        values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """pymodbus' hook, called before every answer (simdevice.py:91-115)."""
        self.requests.append((self.unit, function_code, address))
        if function_code != _READ_HOLDING or values is not None:
            return ExcCodes.ILLEGAL_FUNCTION
        image = self.spec.image
        first = address - image.base
        if first < 0 or first + count > len(image.words):
            return ExcCodes.ILLEGAL_ADDRESS
        for offset in range(count):
            registers[address - start + offset] = image.words[first + offset]
        return None
