"""Free loopback ports for the tests' own servers (brokers, simulators, web pages).

A port from ``bind(("127.0.0.1", 0))`` lies in Linux's ephemeral range (32768-60999), the
range every outgoing connection on the machine takes its local port from. Between picking
it and a slow server binding it (a RabbitMQ node boots for seconds), a connection of
another test worker can take it, and the server fails to start (seen in CI: the node
accepted the first CONNECT, then died). So ports come from below that range, where no
connection takes one on its own: each xdist worker walks a slice of its own, from a
random start, and a port is handed out only if binding it works now.
"""

from __future__ import annotations

import os
import random
import re
import socket

HOST = "127.0.0.1"
FIRST, SLICE, SLICES = 10000, 2000, 11  # 10000-31999: below the ephemeral range

_next: list[int] = []


def _slice() -> range:
    """This process's ports: one slice per xdist worker (gw0, gw1…), the last for none."""
    found = re.fullmatch(r"gw(\d+)", os.environ.get("PYTEST_XDIST_WORKER", ""))
    index = int(found.group(1)) % (SLICES - 1) if found else SLICES - 1
    start = FIRST + index * SLICE
    return range(start, start + SLICE)


def free_port(host: str = HOST) -> int:
    """A port on ``host`` that nothing is bound to now, never one handed out in the last
    ``SLICE`` calls of this process."""
    ports = _slice()
    if not _next:
        _next.append(random.randrange(len(ports)))
    for _ in range(len(ports)):
        port = ports[_next[0] % len(ports)]
        _next[0] += 1
        with socket.socket() as probe:
            try:
                probe.bind((host, port))
            except OSError:
                continue
        return port
    raise RuntimeError(f"no free port in {ports.start}-{ports.stop - 1} on {host}")
