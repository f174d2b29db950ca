"""The bridge's own CPU and memory with 1, 50 and 247 simulated devices.

Every device is a soft starter (52 entities on 48 registers; the device reads at most 6
registers at a time, so a full scan is 10 reads: 3 for the fast class, 7 for the
settings), on Modbus TCP, its fast class polled every second. Two loads: every register
every second (settings too: 10 reads per device per second), and the settings at the
default 60 s (3.1 reads per device per second). Cases: one device; 50 and 247 units
behind one TCP gateway (one port, so one frame in flight, as a gateway to a serial line
allows); 50 devices each on its own TCP port (own bus, own connection). Readings wander
every second, so state messages flow (the JSON of the device and each changed value).

Each process is separate so the figures are the bridge's own: mosquitto (private, on a
free loopback port, ``tests/integration/mosquitto.py``), the simulator (this file with
``serve``: every port in one process), the bridge (``modbus-mqtt-bridge run -c`` on a
generated config; MQTT 5, QoS 1, the defaults) and, here, an MQTT subscriber counting
messages. After a warm-up the bridge is measured for a fixed window: CPU (utime + stime
from ``/proc/<pid>/stat``, % of one core), RSS (``VmRSS`` sampled every second,
``VmHWM`` at the end: the peak since start), MQTT messages/s at the subscriber, and the
fast poll period achieved: per device, the configured 1 s scaled by the requests it
should make over the requests it made in ``<base>/bridge/health`` (every 10 s).

``--output`` sets ``mqtt.output`` (json, the default; values; both, as deploy/config.yaml
has it) and ``--case`` keeps only the case of that label.

    .venv/bin/python bench/scale.py [seconds] [warm-up seconds] [--output both] [--case TEXT]
    .venv/bin/python bench/scale.py profile [seconds] [--output both] [--case TEXT]
        # where the CPU goes (50 devices, one gateway, settings 60 s, unless --case)
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import contextlib
import json
import os
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the private broker of the tests

from bridge.config import MqttConfig
from bridge.core.entity import PollClass
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.core.planner import limits_for, plan_reads
from bridge.modbus.simulator import SimulatedUnit, Simulator
from bridge.mqtt import MqttClient
from tests.integration.mosquitto import Broker
from tests.ports import free_port

MAPPING = "soft_starter"
PERIOD = 1.0  # the fast class
HEALTH_INTERVAL = 10.0
CASES = (  # label, units per port, ports, settings period (slow class)
    ("1 device", 1, 1, PERIOD),
    ("50 devices, one gateway", 50, 1, PERIOD),
    ("50 devices, own ports", 1, 50, PERIOD),
    ("247 devices, one gateway", 247, 1, PERIOD),
    ("1 device, settings 60 s", 1, 1, 60.0),
    ("50 devices, one gateway, settings 60 s", 50, 1, 60.0),
    ("50 devices, own ports, settings 60 s", 1, 50, 60.0),
    ("247 devices, one gateway, settings 60 s", 247, 1, 60.0),
)
PROFILED = CASES[5]
BRIDGE = Path(sys.executable).with_name("modbus-mqtt-bridge")
TICK = os.sysconf("SC_CLK_TCK")


def reads_per_second(slow: float) -> float:
    """The requests one device should make per second: its fast class every ``PERIOD``,
    its settings every ``slow`` seconds."""
    mapping = load_mapping(builtin_mapping_path(MAPPING))
    limits = limits_for(mapping)
    rate = 0.0
    for poll_class, period in ((PollClass.FAST, PERIOD), (PollClass.SLOW, slow)):
        points = [p for p in mapping.points().values() if p.entity.poll_class is poll_class]
        rate += len(plan_reads(points, limits).reads) / period
    return rate


# --- processes ---------------------------------------------------------------------------


def cpu_seconds(pid: int) -> float:
    """utime + stime of a process (every thread), from /proc/<pid>/stat."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK


def memory_kib(pid: int, name: str) -> int:
    """``VmRSS`` or ``VmHWM`` of a process, in KiB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{name}:"):
            return int(line.split()[1])
    raise KeyError(name)


def bridge_config(  # noqa: PLR0917 - the bench's own helper
    folder: Path,
    url: str,
    ports: list[int],
    units: int,
    poll: dict[str, float],
    output: str = "json",
) -> Path:
    """A config polling ``units`` soft starters behind each port, one bus per port."""
    buses = [
        {"id": f"g{i}", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port, "timeout": 1}
        for i, port in enumerate(ports)
    ]
    devices = [
        {"id": f"g{i}-u{unit}", "bus": f"g{i}", "unit": unit, "mapping": MAPPING, "poll": poll}
        for i in range(len(ports))
        for unit in range(1, units + 1)
    ]
    config = {
        "mqtt": {"url": url, "base_topic": "modbus", "client_id": "bench-bridge", "output": output},
        "bridge": {"health_interval": HEALTH_INTERVAL},
        "buses": buses,
        "devices": devices,
    }
    path = folder / "bridge.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


@contextlib.contextmanager
def process(args: list[str], log: Path) -> Iterator[subprocess.Popen[bytes]]:
    """A child process for the duration of the block, its output in ``log``."""
    with log.open("wb") as out:
        child = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT)  # noqa: S603
    try:
        yield child
    finally:
        child.terminate()
        try:
            child.wait(10)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait(10)


# --- measuring ---------------------------------------------------------------------------


@dataclass
class Listener:
    """Counts every message under ``modbus/#``; keeps the health documents with their time."""

    messages: int = 0
    health: list[tuple[float, dict[str, Any]]] = field(default_factory=list)

    async def run(self, client: MqttClient) -> None:
        async for message in client.messages():
            self.messages += 1
            if message.topic == "modbus/bridge/health":
                self.health.append((time.monotonic(), json.loads(message.payload)))


@dataclass(frozen=True)
class Figures:
    cpu: float  # % of one core
    rss_max: float  # MiB, sampled in the window
    hwm: float  # MiB, peak since start
    messages: float  # per second
    period_median: float  # s
    period_max: float  # s
    utilisation: float  # busiest bus, 0..1
    sim_cpu: float  # % of one core, the simulator process


def periods(first: dict[str, Any], last: dict[str, Any], expected: float) -> list[float]:
    """Each device's fast poll period between two health documents: ``PERIOD`` scaled by
    the requests per second it should make over those it made."""
    seconds = last["uptime_s"] - first["uptime_s"]
    found = []
    for device, now in last["devices"].items():
        rate = (now["requests"] - first["devices"][device]["requests"]) / seconds
        found.append(PERIOD * expected / rate if rate else float("inf"))
    return found


async def measure_bridge(
    pids: tuple[int, int], url: str, slow: float, warmup: float, seconds: float
) -> Figures:
    pid, sim_pid = pids
    listener = Listener()
    async with MqttClient(MqttConfig(url=url), will_topic="bench/state", client_id="bench") as c:
        task = asyncio.create_task(listener.run(c))
        await c.subscribe("modbus/#", qos=0)  # no acknowledgements to keep up with
        await asyncio.sleep(warmup)
        listener.messages = 0
        started, cpu, sim_cpu = time.monotonic(), cpu_seconds(pid), cpu_seconds(sim_pid)
        rss = []
        while time.monotonic() - started < seconds:
            rss.append(memory_kib(pid, "VmRSS"))
            await asyncio.sleep(1)
        elapsed = time.monotonic() - started
        cpu, sim_cpu = cpu_seconds(pid) - cpu, cpu_seconds(sim_pid) - sim_cpu
        messages, hwm = listener.messages, memory_kib(pid, "VmHWM")
        task.cancel()
    window = [doc for at, doc in listener.health if at >= started]
    expected = reads_per_second(slow)
    found = periods(window[0], window[-1], expected) if len(window) > 1 else [0.0]
    busiest = max(bus["utilisation"] for bus in window[-1]["buses"].values()) if window else 0
    return Figures(
        cpu=100 * cpu / elapsed,
        rss_max=max(rss) / 1024,
        hwm=hwm / 1024,
        messages=messages / elapsed,
        period_median=statistics.median(found),
        period_max=max(found),
        utilisation=busiest,
        sim_cpu=100 * sim_cpu / elapsed,
    )


@contextlib.asynccontextmanager
async def bridge_process(  # noqa: PLR0917 - the bench's own helper
    folder: Path,
    url: str,
    units: int,
    ports: int,
    poll: dict[str, float],
    profile: Path | None = None,
    output: str = "json",
) -> AsyncIterator[tuple[int, int]]:
    """The simulator (``units`` per port) and the bridge, each in its own process; yields
    their process ids once the bridge is started (under cProfile, writing ``profile``)."""
    chosen = [free_port() for _ in range(ports)]
    serve = [sys.executable, __file__, "serve", str(units), *map(str, chosen)]
    with process(serve, folder / "simulator.log") as sim:
        await listening(chosen)
        config = bridge_config(folder, url, chosen, units, poll, output)
        run = [str(BRIDGE), "run", "-c", str(config), "--log-level", "warning"]
        if profile is not None:
            run = [sys.executable, "-m", "cProfile", "-o", str(profile), *run]
        with process(run, folder / "bridge.log") as bridge:
            yield bridge.pid, sim.pid


async def listening(ports: list[int], within: float = 60.0) -> None:
    deadline = time.monotonic() + within
    for port in ports:
        while True:
            try:
                _, writer = await asyncio.open_connection("127.0.0.1", port)
            except OSError:
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.2)
                continue
            writer.close()
            await writer.wait_closed()
            break


async def run_case(  # noqa: PLR0917 - the bench's own helper
    units: int, ports: int, slow: float, warmup: float, seconds: float, output: str
) -> Figures:
    with tempfile.TemporaryDirectory() as name:
        broker = Broker(Path(name))
        broker.start()
        try:
            poll = {"fast": PERIOD, "slow": slow}
            folder = Path(name)
            async with bridge_process(folder, broker.url, units, ports, poll, None, output) as pids:
                return await measure_bridge(pids, broker.url, slow, warmup, seconds)
        finally:
            broker.stop()


async def profile(seconds: float, output: str, case: str) -> None:
    """Run the bridge of ``PROFILED`` (or the case labelled ``case``) under cProfile with
    ``mqtt.output`` at ``output``; print where its CPU time goes, by area and by function."""
    label, units, ports, slow = next((c for c in CASES if c[0] == case), PROFILED)
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        broker = Broker(folder)
        broker.start()
        try:
            poll = {"fast": PERIOD, "slow": slow}
            async with bridge_process(
                folder, broker.url, units, ports, poll, folder / "p", output
            ):
                await asyncio.sleep(seconds)
        finally:
            broker.stop()
        stats = pstats.Stats(str(folder / "p")).stats  # type: ignore[attr-defined]
    areas: collections.Counter[str] = collections.Counter()
    modules: collections.Counter[str] = collections.Counter()
    functions: collections.Counter[str] = collections.Counter()
    for (file, line, function), (_, _, own, _, _) in stats.items():
        if "select.epoll" not in function:  # waiting for I/O: idle
            areas[_area(file, function)] += own
            where = file.rsplit("-packages/", maxsplit=1)[-1].rsplit("/bridge/", maxsplit=1)[-1]
            functions[f"{where}:{line} {function}"] += own
        if "/bridge/" in file:
            modules["bridge/" + file.rsplit("/bridge/", maxsplit=1)[-1]] += own
    busy = sum(areas.values())
    print(
        f"{label}, mqtt.output: {output}: {seconds:g} s under cProfile (start-up included), "
        f"{busy:.1f} s busy\n"
    )
    print("| where | s | % of busy |")
    print("| --- | ---: | ---: |")
    for area, own in [*areas.most_common(), *modules.most_common(6)]:
        print(f"| {area} | {own:.2f} | {100 * own / busy:.1f} |")
    print("\n| function (own time) | s | % of busy |")
    print("| --- | ---: | ---: |")
    for function, own in functions.most_common(25):
        print(f"| {function} | {own:.2f} | {100 * own / busy:.1f} |")


def _area(file: str, function: str) -> str:
    if "/bridge/" in file:
        return "the bridge's own code (modules below)"
    library = (
        file.split("site-packages/")[1].split("/", maxsplit=1)[0] if "-packages/" in file else ""
    )
    if library in ("paho", "aiomqtt"):
        return "MQTT client (paho, aiomqtt)"
    if library == "pymodbus":
        return "Modbus client (pymodbus)"
    if library:
        return "other libraries (pydantic, yaml: mostly start-up)"
    if "socket" in function and ("send" in function or "recv" in function):
        return "socket send/recv (system calls)"
    if "/asyncio/" in file or "selectors" in file:
        return "event loop (asyncio)"
    return "standard library and builtins (json, enum, ...)"


# --- the simulator process ----------------------------------------------------------------


async def serve(units: int, ports: list[int]) -> None:
    """Serve ``units`` soft starters (units 1..units) on each port, all in this process."""
    mapping = load_mapping(builtin_mapping_path(MAPPING))
    async with asyncio.TaskGroup() as group:
        for port in ports:
            specs = [SimulatedUnit(u, mapping) for u in range(1, units + 1)]
            group.create_task(Simulator(specs, tick=PERIOD).serve_tcp("127.0.0.1", port))


# --- report ------------------------------------------------------------------------------


async def main(seconds: float, warmup: float, output: str, case: str) -> None:
    print(
        f"{MAPPING}, fast class every {PERIOD:g} s, settings every {PERIOD:g} s unless stated "
        f"(reads per device per second: {reads_per_second(PERIOD):.1f}, or "
        f"{reads_per_second(60):.1f}), Modbus TCP on loopback; {warmup:g} s warm-up, then "
        f"{seconds:g} s measured; mqtt.output: {output}\n"
    )
    header = [
        *("case", "bridge CPU % of a core", "RSS max MiB", "peak RSS (VmHWM) MiB"),
        *("MQTT msg/s", "fast period median s", "fast period max s", "busiest bus %"),
        "simulator CPU %",
    ]
    print("| " + " | ".join(header) + " |")
    print("| --- |" + " ---: |" * (len(header) - 1))
    for label, units, ports, slow in CASES:
        if case and label != case:
            continue
        f = await run_case(units, ports, slow, warmup, seconds, output)
        cells = [
            *(label, f"{f.cpu:.1f}", f"{f.rss_max:.1f}", f"{f.hwm:.1f}", f"{f.messages:.0f}"),
            *(f"{f.period_median:.2f}", f"{f.period_max:.2f}", f"{100 * f.utilisation:.0f}"),
            f"{f.sim_cpu:.1f}",
        ]
        print("| " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    if sys.argv[1:2] == ["serve"]:
        asyncio.run(serve(int(sys.argv[2]), [int(p) for p in sys.argv[3:]]))
    else:
        profiling = sys.argv[1:2] == ["profile"]
        parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
        parser.add_argument("seconds", type=float, nargs="?", default=60.0)
        if not profiling:
            parser.add_argument("warmup", type=float, nargs="?", default=20.0)
        parser.add_argument("--output", choices=("json", "values", "both"), default="json")
        parser.add_argument("--case", default="", help="only the case of this label")
        a = parser.parse_args(sys.argv[2:] if profiling else sys.argv[1:])
        if profiling:
            asyncio.run(profile(a.seconds, a.output, a.case))
        else:
            asyncio.run(main(a.seconds, a.warmup, a.output, a.case))
