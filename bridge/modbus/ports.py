"""The host's serial ports, for the page's "add a bus": pyserial's list, ``/dev/serial/by-id``
names first (they survive a replug and a reboot; ``/dev/ttyUSB0`` may not), each with its
description, at most ``MAX_PORTS``. A port the page may open is one of these (``listed``):
nothing else on the host is opened as a serial line.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from serial.tools import list_ports

MAX_PORTS = 64
BY_ID = Path("/dev/serial/by-id")


@dataclass(frozen=True, slots=True)
class SerialPort:
    """One port: ``path`` as a config should name it (the by-id link when there is one)."""

    path: str
    device: str  # the kernel's name, /dev/ttyUSB0
    description: str

    def as_dict(self) -> dict[str, str]:
        return {"path": self.path, "device": self.device, "description": self.description}


def serial_ports(by_id: Path = BY_ID, limit: int = MAX_PORTS) -> list[SerialPort]:
    """The ports pyserial finds, by-id names first, then by name; blocking (sysfs reads)."""
    links: dict[str, str] = {}
    if by_id.is_dir():
        for link in sorted(by_id.iterdir())[: 4 * limit]:
            links.setdefault(os.path.realpath(link), str(link))
    ports = [
        SerialPort(
            links.get(os.path.realpath(info.device), info.device),
            info.device,
            info.description if info.description not in (None, "n/a") else "",
        )
        for info in list_ports.comports()[: 4 * limit]
    ]
    ports.sort(key=lambda p: (not p.path.startswith(f"{by_id}/"), p.path))
    return ports[:limit]


def listed(path: str, ports: list[SerialPort]) -> bool:
    """Whether ``path`` names one of ``ports`` (its by-id link or its kernel name)."""
    return any(path in (p.path, p.device) for p in ports)


def same_port(a: str, b: str) -> bool:
    """Two names of one device (a by-id link and its target), without opening either."""
    return a == b or os.path.realpath(a) == os.path.realpath(b)
