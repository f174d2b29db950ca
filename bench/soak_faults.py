"""``make soak``: a month of a site's faults in an hour, invariants checked as it runs.

The real bridge runs in its own process (``modbus-mqtt-bridge run -c`` on a config from
bench/soak_site.py, ``--log-format json``) against the simulator (this process: a Modbus
TCP port and an RTU line on a pty pair whose replies can be made noisy or torn) and a
private mosquitto (tests/integration/mosquitto.py). A seeded schedule
(bench/soak_schedule.py) throws the faults; an observer (an MQTT client on ``#``) and
the simulators' write logs record what the bridge does, and the checkers of
bench/soak_invariants.py run over the records every ``CHECK_EVERY`` seconds. A violation
is printed when found, with the schedule position of the last fault thrown before it,
and the run goes on; the report at the end lists them all and the exit code is 1.

    .venv/bin/python bench/soak_faults.py [DURATION] [--seed N]    # 5m, 1h (default 5m)

Bench modules, not a package: the soak is a bench like bench/soak.py (it reuses
bench/scale.py's process helpers), and tests/unit/test_soak.py checks its pure parts the
way tests/unit/test_bench_peers.py checks bench/peer_configs.py.
"""

from __future__ import annotations

import argparse
import asyncio
import bisect
import contextlib
import functools
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the private broker of the tests

from scale import memory_kib, process
from soak_observer import Observer, Publisher
from soak_record import Records
from soak_schedule import build_schedule, parse_duration, summary
from soak_site import build_config, device_facts, units
from soak_throw import Thrower

from bridge.modbus.null_modem import null_modem
from bridge.modbus.simulator import Simulator
from tests.integration.mosquitto import Broker
from tests.ports import free_port

CHECK_EVERY = 10.0
SAMPLE_EVERY = 5.0


class Soak:
    """One run: the processes, the faults and the records."""

    def __init__(self, seconds: float, seed: int, folder: Path) -> None:
        self.seconds, self.seed, self.folder = seconds, seed, folder
        self.schedule = build_schedule(seed, seconds)
        self.broker = Broker(folder)
        self.simulators = {
            "tcp": Simulator(units("tcp"), seed=seed),
            "rs485": Simulator(units("rs485"), seed=seed + 1),
        }
        self.records = Records(device_facts(self.simulators))
        self.bridge_logs: list[Path] = []
        self.started = 0.0

    def position_at(self, at: float) -> int:
        """The schedule position of the last fault thrown at or before ``at`` (-1: none)."""
        times = [self.started + f.at for f in self.schedule]
        return bisect.bisect_right(times, at) - 1

    async def run(self) -> int:
        self.broker.start()
        try:
            with (
                null_modem(self.records.line) as (device_end, client_end),
                contextlib.ExitStack() as stack,
            ):
                self.records.line.later = asyncio.get_running_loop().call_later
                return await self._with_line(device_end, client_end, stack)
        finally:
            self.broker.stop()

    async def _with_line(
        self, device_end: str, client_end: str, stack: contextlib.ExitStack
    ) -> int:
        tcp_port, gateway_port = free_port(), free_port()
        async with asyncio.TaskGroup() as group:
            serving = [
                group.create_task(self.simulators["tcp"].serve_tcp("127.0.0.1", tcp_port)),
                group.create_task(
                    self.simulators["rs485"].serve_serial(device_end, baudrate=19200)
                ),
            ]
            for simulator in self.simulators.values():
                await asyncio.wait_for(simulator.ready.wait(), 10)
            config = functools.partial(
                build_config, self.folder, self.broker.url, tcp_port, client_end, gateway_port
            )
            config(False)
            observer = Observer(self.broker.port, self.records)
            publisher = Publisher(self.broker.port)
            with observer, publisher:
                self.started = time.monotonic()
                bridge = self._start_bridge(stack)
                thrower = Thrower(self, publisher, config, gateway_port)
                code = await self._watch(bridge, stack, thrower)
            for task in serving:
                task.cancel()
        return code

    def _start_bridge(self, stack: contextlib.ExitStack) -> subprocess.Popen[bytes]:
        log = self.folder / f"bridge-{len(self.bridge_logs)}.log"
        self.bridge_logs.append(log)
        self.records.log_offsets[log] = 0
        config = str(self.folder / "bridge.yaml")
        run = [sys.executable, "-m", "bridge.cli", "run", "-c", config, "--log-format", "json"]
        return stack.enter_context(process(run, log))

    async def _watch(
        self, bridge: subprocess.Popen[bytes], stack: contextlib.ExitStack, thrower: Thrower
    ) -> int:
        end = self.started + self.seconds
        next_check = self.started + CHECK_EVERY
        async with asyncio.TaskGroup() as group:
            faults = group.create_task(thrower.throw_all(self.schedule, self.started))
            while time.monotonic() < end:
                await asyncio.sleep(0.25)
                now = time.monotonic()
                self.records.digest(self.simulators, now)
                for log in self.bridge_logs:
                    self.records.read_log(log, now)
                if bridge.poll() is not None:
                    self.records.exited(now, bridge.returncode, self.position_at(now))
                    bridge = self._start_bridge(stack)
                thrower.bridge_pid = bridge.pid
                if now >= self.records.next_sample:
                    self.records.sample(now, bridge.pid, memory_kib, SAMPLE_EVERY)
                if now >= next_check:
                    self.records.check(now, self.position_at)
                    next_check = now + max(CHECK_EVERY, (now - self.started) / 60)
            faults.cancel()
        for _ in range(8):  # the last writes and publishes arrive
            await asyncio.sleep(0.25)
            now = time.monotonic()
            self.records.digest(self.simulators, now)
        self.records.check(now, self.position_at, final=True)
        return 1 if self.records.violations else 0


def report(soak: Soak, seconds: float) -> str:
    r = soak.records
    lines = [
        f"## soak: seed {soak.seed}, {seconds / 60:g} min\n",
        "| fault | thrown |",
        "| --- | ---: |",
        *(
            f"| {kind} | {r.counts.get('thrown ' + kind, 0)} of {n} |"
            for kind, n in summary(soak.schedule).items()
        ),
        "",
        "| what | count |",
        "| --- | ---: |",
        *(f"| {k} | {v} |" for k, v in sorted(r.counts.items()) if not k.startswith("thrown ")),
        "",
        *r.resource_lines(),
        *r.health_lines(),
        "",
        f"Violations: {len(r.violations)}",
        *(
            f"- [{v.position}] t+{v.at - soak.started:.0f} s {v.invariant}: {v.detail}"
            for v in r.violations
        ),
    ]
    if r.warning_messages:
        lines += ["", "Most frequent WARNING+ log messages:"]
        lines += [f"- {n} x {m}" for m, n in r.warning_messages.most_common(8)]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("duration", nargs="?", default="5m", help="5m, 1h, 90s (default 5m)")
    parser.add_argument("--seed", type=int, default=int(os.environ.get("SEED") or 1))
    args = parser.parse_args()
    seconds = parse_duration(args.duration)
    root = str(Path(__file__).resolve().parents[1])  # the bridge of this checkout, not another
    os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))
    with tempfile.TemporaryDirectory(prefix="soak-") as name:
        soak = Soak(seconds, args.seed, Path(name))
        print(
            f"soak: seed {args.seed}, {seconds:g} s, {len(soak.schedule)} faults; folder {name}",
            flush=True,
        )
        code = asyncio.run(soak.run())
        print(report(soak, seconds), flush=True)
        if code:  # the logs outlive the run's folder, for the violations' story
            kept = Path(tempfile.gettempdir()) / f"soak-seed{args.seed}-logs"
            kept.mkdir(exist_ok=True)
            for log in Path(name).glob("*.log"):
                shutil.copy(log, kept / log.name)
            print(f"logs kept in {kept}", flush=True)
    raise SystemExit(code)


if __name__ == "__main__":
    # SIGPIPE stays ignored (Python's default): with SIG_DFL a write to a socket whose
    # broker was just killed (the broker_restart fault) killed the driver itself
    main()
