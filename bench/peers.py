"""This bridge beside the two Python peers users compare it to, on one workload.

The peers come from PyPI, each in its own venv under ``bench/.peers/`` (created on first
use, reused while its requirements stay the same; git ignores the folder):
``modbus4mqtt==0.7.1`` as it resolves (pymodbus 2.5, paho 1.6) and ``modbus2mqtt==0.73``
with ``pymodbus==3.8.6`` pinned beside it (0.73 still calls ``slave=``).

The workload (``bench/peer_configs.py``): one Nastec VASCO pump inverter, 40 registers /
38 values polled every 1 s over Modbus TCP, one register per request as the device
demands, and 20 run/stop commands. All three configs are generated from one list of
entity keys, written as each project's README describes; this bridge reads a mapping
trimmed to those keys (the shipped ``nastec_vasco.yaml`` with every other entity removed,
``pump40.yaml`` next to the generated config). The device is the project's simulator in
its own process (``bench/peer_device.py``: ``latency`` seconds per transaction, 20 ms by
default, about one single-register transaction at 9600 bit/s, so a serial-like bus; a
dead unit 2 beside it) behind a relay that logs every request. Each run has its own
mosquitto (``tests/integration/mosquitto.py``, ``set_tcp_nodelay true`` as deploy ships
it) on a free loopback port, and every bridge process is stopped by PID.

Per bridge, two runs. The first, polling unit 1 only, measures in order:

* over the ``--seconds`` window (30 s) after a 5 s warm-up: CPU (utime + stime of the
  bridge process and its children, ``/proc/<pid>/stat``: % of one core, and per poll
  cycle), the poll period achieved (mean interval between the relay's reads of the first
  register of the list), and MQTT bytes at a subscriber to ``#``: topic + payload of
  every message the bridge sent (MQTT headers not counted), per second and per poll
  cycle (per second x the period achieved);
* peak RSS: ``VmHWM`` of the process(es) (``/proc/<pid>/status``) after the window;
* ``--commands`` run/stop commands, each the opposite of the value last seen, after a
  random 0.2-1.2 s pause: from the publish (QoS 1) to the new value on MQTT;
* a 5 s broker outage (mosquitto stopped, then started on the same port; no persistence,
  so nothing retained survives): the first value on MQTT after the broker accepts
  connections again (the subscriber is back within milliseconds), and how many of the
  38 values came back whole in the 10 s after.

The second run adds the dead unit 2 to each config (modbus4mqtt: a second process) and
measures unit 1's poll period over the same window after a 10 s warm-up; a bridge that
does not poll unit 1 twice in the window gets a lower bound (``> N s``: the time since
its last poll of unit 1). All of it takes about 7 minutes; ``--keep DIR`` keeps every
run's configs and logs (bridge, device, relay requests, MQTT messages seen).

    .venv/bin/python bench/peers.py [--seconds 30] [--commands 20] [--latency 0.02]
                                    [--only bridge|bridge-values|modbus4mqtt|modbus2mqtt]...
                                    [--keep DIR]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import random
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import aiomqtt

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the private broker of the tests

from latency import NodelayBroker
from peer_configs import DEAD_UNIT, KEYS, UNIT, registers, write_configs
from peer_device import read_requests, serve
from peer_kinds import KINDS, Kind, Run, truth
from scale import cpu_seconds, listening, memory_kib, process

from bridge.config import MqttConfig
from bridge.mqtt import MqttClient, MqttDisconnectedError
from tests.ports import free_port

WARMUP, DEAD_WARMUP = 5.0, 10.0
OUTAGE, AFTER_OUTAGE = 5.0, 10.0
COMMAND_TIMEOUT = 10.0
FIRST_VALUES = 30.0  # seconds a bridge may take to publish every value once


# --- processes ---------------------------------------------------------------------------


def tree(pid: int) -> list[int]:
    """``pid`` and its descendants."""
    found = [pid]
    for task in Path(f"/proc/{pid}/task").glob("*"):
        with contextlib.suppress(OSError):
            for child in (task / "children").read_text().split():
                found += tree(int(child))
    return found


def tree_cpu(pids: list[int]) -> float:
    return sum(cpu_seconds(p) for pid in pids for p in tree(pid))


def tree_hwm_kib(pids: list[int]) -> int:
    return sum(memory_kib(p, "VmHWM") for pid in pids for p in tree(pid))


# --- the subscriber ----------------------------------------------------------------------


@dataclass
class Seen:
    at: float
    topic: str
    size: int  # topic + payload bytes
    names: frozenset[str]  # the values it carries (topic names, see Kind.read)


@dataclass
class Watcher:
    """Subscribes to ``#``; keeps what arrived and resolves a waiting command."""

    kind: Kind
    seen: list[Seen] = field(default_factory=list)
    state: bool | None = None  # the command key's last value
    waiting: tuple[bool, asyncio.Future[float]] | None = None
    client: MqttClient | None = None
    task: asyncio.Task[None] | None = None

    async def start(self, url: str) -> None:
        """Connect (retrying while the broker is not up) and subscribe."""
        connected: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self.task = asyncio.create_task(self._run(url, connected))
        await connected

    async def _run(self, url: str, connected: asyncio.Future[None]) -> None:
        while True:
            try:
                async with MqttClient(MqttConfig(url=url), will_topic="bench/state") as client:
                    await client.subscribe("#", qos=0)
                    self.client = client
                    connected.set_result(None)
                    await self._receive(client)
                    return
            except MqttDisconnectedError:
                if connected.done():
                    return
                await asyncio.sleep(0.01)

    async def _receive(self, client: MqttClient) -> None:
        async for message in client.messages():
            arrived = time.monotonic()
            if message.topic.startswith("bench/"):
                continue
            values = self.kind.read(message.topic, message.payload)
            size = len(message.topic.encode()) + len(message.payload)
            self.seen.append(Seen(arrived, message.topic, size, frozenset(values)))
            command = self.kind.command_name
            if command in values:
                self.state = truth(values[command])
                wanted = self.waiting
                if wanted is not None and wanted[0] == self.state and not wanted[1].done():
                    wanted[1].set_result(arrived)

    def names_since(self, since: float) -> set[str]:
        return {n for s in self.seen if s.at >= since for n in s.names}


# --- one bridge ---------------------------------------------------------------------------


@dataclass
class Figures:
    cpu: float = 0.0  # % of one core
    hwm_mib: float = 0.0
    period: float = 0.0  # s, unit 1 alone
    bytes_per_second: float = 0.0
    latencies: list[float] = field(default_factory=list)  # command -> value on MQTT, s
    lost: int = 0  # commands whose value never came back
    back: int = 0  # values republished after the outage
    first: float | None = None  # s from the broker back to the first value
    dead_period: str = "-"
    notes: list[str] = field(default_factory=list)


@contextlib.asynccontextmanager
async def setup(
    kind: Kind, units: list[int], latency: float, folder: Path
) -> AsyncIterator[tuple[NodelayBroker, Watcher, list[subprocess.Popen[bytes]], Path]]:
    """Broker, device, subscriber and bridge process(es) for one run; yields the broker,
    the subscriber, the bridge processes and the relay's request log. What the
    subscriber saw goes to ``mqtt.log`` (``<time> <bytes> <topic>``) beside it."""
    broker = NodelayBroker(folder)
    broker.start()
    try:
        port, log = free_port(), folder / "requests.log"
        serve_args = [sys.executable, __file__, "serve", str(port), str(latency), str(log)]
        with contextlib.ExitStack() as stack:
            stack.enter_context(process(serve_args, folder / "device.log"))
            await listening([port])
            paths = write_configs(folder, broker.url, port, units)
            watcher = Watcher(kind)
            await watcher.start(broker.url)
            children = [
                stack.enter_context(process(argv, folder / f"{kind.name}-{i}.log"))
                for i, argv in enumerate(kind.argv(Run(paths, broker.port, port, units)))
            ]
            try:
                yield broker, watcher, children, log
            finally:
                lines = (f"{s.at:.6f} {s.size} {s.topic}\n" for s in watcher.seen)
                (folder / "mqtt.log").write_text("".join(lines))
            for child in children:
                if child.poll() is not None:
                    raise RuntimeError(f"{kind.name} exited early ({child.returncode})")
            if watcher.task is not None:
                watcher.task.cancel()
    finally:
        broker.stop()


def marker_reads(log: Path) -> list[float]:
    """When unit 1's first register was read: once per poll cycle."""
    first = registers()[0].address
    return [
        r.at
        for r in read_requests(log)
        if r.unit == UNIT and r.function == 3 and r.address == first
    ]


def mean_gap(times: list[float], since: float, until: float) -> float | None:
    inside = [t for t in times if since <= t < until]
    gaps = [b - a for a, b in itertools.pairwise(inside)]
    return statistics.fmean(gaps) if gaps else None


@contextlib.contextmanager
def run_folder(keep: Path | None, label: str) -> Iterator[Path]:
    """A temporary folder for one run, or ``keep/label`` (kept) with ``--keep``."""
    if keep is None:
        with tempfile.TemporaryDirectory() as name:
            yield Path(name)
        return
    folder = keep / label
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    yield folder


async def wait_for_values(watcher: Watcher, kind: Kind) -> None:
    deadline = time.monotonic() + FIRST_VALUES
    while kind.complete(watcher.names_since(0)) < len(KEYS) and time.monotonic() < deadline:
        await asyncio.sleep(0.2)


async def commands(watcher: Watcher, kind: Kind, count: int, figures: Figures) -> None:
    rng = random.Random(1)  # noqa: S311 - pauses, not secrets
    for _ in range(count):
        await asyncio.sleep(rng.uniform(0.2, 1.2))
        wanted = not watcher.state
        arrived: asyncio.Future[float] = asyncio.get_running_loop().create_future()
        watcher.waiting = (wanted, arrived)
        topic, payload = kind.command(wanted)
        assert watcher.client is not None
        sent = time.monotonic()
        await watcher.client.publish(topic, payload, qos=1)
        try:
            figures.latencies.append(await asyncio.wait_for(arrived, COMMAND_TIMEOUT) - sent)
        except TimeoutError:
            figures.lost += 1


async def outage(broker: NodelayBroker, watcher: Watcher, kind: Kind, figures: Figures) -> None:
    broker.stop()
    await asyncio.sleep(OUTAGE)
    broker.start()  # same port; returns once it accepts connections
    back = time.monotonic()
    await watcher.start(broker.url)
    await asyncio.sleep(AFTER_OUTAGE)
    figures.back = kind.complete(watcher.names_since(back))
    firsts = [s.at for s in watcher.seen if s.at >= back and s.names]
    figures.first = min(firsts) - back if firsts else None


async def measure(kind: Kind, args: argparse.Namespace) -> Figures:
    figures = Figures()
    with run_folder(args.keep, kind.name) as folder:
        await measure_alone(kind, args, folder, figures)
    with run_folder(args.keep, f"{kind.name}-dead-unit") as folder:
        await measure_beside_dead_unit(kind, args, folder, figures)
    return figures


async def measure_alone(
    kind: Kind, args: argparse.Namespace, folder: Path, figures: Figures
) -> None:
    """Unit 1 alone: the window, the commands, the broker outage."""
    async with setup(kind, [UNIT], args.latency, folder) as (broker, watcher, children, log):
        pids = [c.pid for c in children]
        await wait_for_values(watcher, kind)
        await asyncio.sleep(WARMUP)
        start, cpu = time.monotonic(), tree_cpu(pids)
        await asyncio.sleep(args.seconds)
        end = time.monotonic()
        figures.cpu = 100 * (tree_cpu(pids) - cpu) / (end - start)
        figures.hwm_mib = tree_hwm_kib(pids) / 1024
        figures.period = mean_gap(marker_reads(log), start, end) or float("inf")
        sent = sum(s.size for s in watcher.seen if start <= s.at < end)
        figures.bytes_per_second = sent / (end - start)
        await commands(watcher, kind, args.commands, figures)
        await outage(broker, watcher, kind, figures)


async def measure_beside_dead_unit(
    kind: Kind, args: argparse.Namespace, folder: Path, figures: Figures
) -> None:
    """Unit 1's poll period with the dead unit 2 in the config too."""
    started = time.monotonic()
    async with setup(kind, [UNIT, DEAD_UNIT], args.latency, folder) as (_, _, children, log):
        await asyncio.sleep(DEAD_WARMUP)
        start = time.monotonic()
        await asyncio.sleep(args.seconds)
        end = time.monotonic()
        reads = marker_reads(log)
    gap = mean_gap(reads, start, end)
    if gap is None:  # not polled twice in the window: at least since its last poll
        last = max((t for t in reads if t < end), default=started)
        figures.dead_period = f"> {end - last:.0f} s"
    else:
        figures.dead_period = f"{gap:.2f} s"
    figures.notes.append(f"{len(children)} process(es) in the dead-unit run")


# --- report ------------------------------------------------------------------------------


def rows(figures: dict[str, Figures], latency: float) -> list[tuple[str, list[str]]]:
    def ms(values: list[float], cut: int) -> str:
        if len(values) < 2:
            return "-"
        return f"{1000 * statistics.quantiles(values, n=100, method='inclusive')[cut - 1]:.1f}"

    found = list(figures.values())
    return [
        (f"command -> value back on MQTT p50, ms ({1000 * latency:g} ms per transaction)",
         [ms(f.latencies, 50) for f in found]),
        ("command -> value back on MQTT p95, ms", [ms(f.latencies, 95) for f in found]),
        ("commands whose value never came back", [f"{f.lost}" for f in found]),
        ("poll period achieved (1 s configured), s", [f"{f.period:.2f}" for f in found]),
        ("live unit beside a dead one: poll period", [f.dead_period for f in found]),
        ("state republished after a 5 s broker outage",
         [f"{f.back}/{len(KEYS)}" for f in found]),
        ("CPU, % of one core (window)", [f"{f.cpu:.2f}" for f in found]),
        ("CPU per poll cycle, ms", [f"{10 * f.cpu * f.period:.1f}" for f in found]),
        ("peak RSS (VmHWM), MiB", [f"{f.hwm_mib:.1f}" for f in found]),
        ("MQTT bytes per poll cycle (topic + payload)",
         [f"{f.bytes_per_second * f.period:.0f}" for f in found]),
        ("MQTT bytes per second (topic + payload)", [f"{f.bytes_per_second:.0f}" for f in found]),
        ("first value on MQTT after the broker is back, s",
         ["-" if f.first is None else f"{f.first:.2f}" for f in found]),
    ]  # fmt: skip


def quiet_lost_sessions(loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
    """The subscriber's session dies with the broker on purpose: not worth a traceback."""
    if not isinstance(context.get("exception"), aiomqtt.MqttError):
        loop.default_exception_handler(context)


async def main(args: argparse.Namespace) -> None:
    asyncio.get_running_loop().set_exception_handler(quiet_lost_sessions)
    kinds = [k for k in KINDS if args.only is None or k.name in args.only]
    for kind in kinds:
        kind.prepare()
    figures = {}
    for kind in kinds:
        print(f"measuring {kind.name} ...", file=sys.stderr, flush=True)
        figures[kind.name] = await measure(kind, args)
    print(
        f"One Nastec VASCO (40 registers / 38 values, one register per read) polled every "
        f"1 s over Modbus TCP, {1000 * args.latency:g} ms per transaction; {args.seconds:g} s "
        f"window, {args.commands} run/stop commands\n"
    )
    print("| figure | " + " | ".join(k.title for k in kinds) + " |")
    print("| --- |" + " ---: |" * len(kinds))
    for label, cells in rows(figures, args.latency):
        print(f"| {label} | " + " | ".join(cells) + " |")
    for kind in kinds:
        print(f"\n{kind.title}: " + "; ".join([*kind.notes, *figures[kind.name].notes]))


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="measuring window")
    parser.add_argument("--commands", type=int, default=20)
    parser.add_argument("--latency", type=float, default=0.02, help="seconds per transaction")
    parser.add_argument(
        "--only", choices=[k.name for k in KINDS], action="append", help="this kind (repeatable)"
    )
    parser.add_argument("--keep", type=Path, help="keep each run's configs and logs here")
    return parser.parse_args(argv)


if __name__ == "__main__":
    if sys.argv[1:2] == ["serve"]:
        asyncio.run(serve(int(sys.argv[2]), float(sys.argv[3]), Path(sys.argv[4])))
    else:
        asyncio.run(main(parse(sys.argv[1:])))
