"""A simulated SunSpec device: a device image's holding registers, served as they are.

``SunSpecUnit(unit, image)`` joins a ``Simulator`` beside mapping units. It answers FC03
within the image (the ``SunS`` marker, its models, the end marker); any read that leaves
the image is refused with 02 (illegal data address) as a real device refuses it, and every
other function code with 01. It takes no writes and nothing moves on its own; a test
changes registers with ``Simulator.set_registers`` (an energy counter, an event bit), or
with ``Simulator.after_read`` once a read was answered (a scale factor that moves between
two requests of one poll).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from pymodbus.constants import ExcCodes
from pymodbus.simulator import DataType, SimData, SimDevice

from bridge.core.simulation import Quirks
from bridge.sunspec.image import DeviceImage

_READ_HOLDING = 3
Request = tuple[int, int, int]  # unit, function code, address
# called with (address, count) of each read answered: the registers to change after it
AfterRead = Callable[[int, int], dict[int, int]]


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
    words: list[int] = field(default_factory=list)  # the image's registers, as they are now
    after_read: list[AfterRead] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.words = list(self.spec.image.words)

    def swap(self, image: DeviceImage) -> None:
        """Serve ``image`` from now on (a firmware update), its registers as it has them."""
        self.spec = SunSpecUnit(self.unit, image)
        self.words = list(image.words)

    def set_registers(self, values: dict[int, int]) -> None:
        """Store ``{address: word}`` within the image (ValueError outside it or not a word)."""
        image = self.spec.image
        for address, word in values.items():
            if not image.base <= address < image.base + len(self.words):
                raise ValueError(f"register {address} is outside unit {self.unit}'s image")
            if not 0 <= word <= 0xFFFF:
                raise ValueError(f"register {address}: {word} is not a 16-bit word")
        for address, word in values.items():
            self.words[address - image.base] = word

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
        first = address - self.spec.image.base
        if first < 0 or first + count > len(self.words):
            return ExcCodes.ILLEGAL_ADDRESS
        for offset in range(count):
            registers[address - start + offset] = self.words[first + offset]
        for hook in self.after_read:  # the answer is taken: what changes after it
            self.set_registers(hook(address, count))
        return None
