"""A virtual RS-485 cable: two pseudo-terminals joined master to master.

``null_modem()`` yields the paths of two serial ports; bytes written to one come out of
the other, with real serial line discipline (raw mode) in between. The simulator serves
one end and the bridge opens the other, so RTU framing and CRC cross a real serial port
without hardware. The relay runs in the current asyncio loop. ``line`` may stand between
the device and the client to damage replies in tests (``line(data, send)`` decides what
``send`` passes on, now or later).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import tty
from collections.abc import Callable, Iterator

Send = Callable[[bytes], None]
Line = Callable[[bytes, Send], None]


@contextlib.contextmanager
def null_modem(line: Line | None = None) -> Iterator[tuple[str, str]]:
    """Yield ``(device_end, client_end)`` serial port paths joined to each other; bytes from
    the device end go through ``line`` if one is given."""
    loop = asyncio.get_running_loop()
    (m1, s1), (m2, s2) = os.openpty(), os.openpty()
    for fd in (s1, s2):
        tty.setraw(fd)

    def pump(source: int, sink: int) -> None:
        with contextlib.suppress(OSError):  # the other end closed: drop the bytes
            os.write(sink, os.read(source, 4096))

    def to_client() -> None:
        try:
            data = os.read(m1, 4096)
        except OSError:  # the device end closed
            return
        if line is None:
            send(data)
        else:
            line(data, send)

    def send(data: bytes) -> None:
        with contextlib.suppress(OSError):
            os.write(m2, data)

    loop.add_reader(m1, to_client)
    loop.add_reader(m2, pump, m2, m1)
    try:
        yield os.ttyname(s1), os.ttyname(s2)
    finally:
        loop.remove_reader(m1)
        loop.remove_reader(m2)
        for fd in (m1, s1, m2, s2):
            os.close(fd)
