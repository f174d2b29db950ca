"""What the soak records as it runs, and the checkers run over it (bench/soak_invariants.py).

``receive`` (the observer's thread) only appends to an inbox; ``digest`` (the soak's loop)
turns the inbox and the simulators' write logs into events and samples the simulators'
values; ``check`` runs every checker over everything recorded and keeps the violations
not seen before, each with the schedule position of the last fault before it.
"""

from __future__ import annotations

import collections
import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from soak_invariants import (
    Availability,
    Published,
    Resets,
    Sample,
    Sent,
    Silence,
    Violation,
    Written,
    check_availability,
    check_bounded,
    check_commands,
    check_counters,
    check_guarded,
    check_log_rate,
    check_values,
    slope_per_hour,
)
from soak_site import BASE, HEALTH_INTERVAL, DeviceFacts, NoisyLine

from bridge.modbus.simulator import Simulator

WARNINGS_PER_MINUTE = 30
RSS_MARGIN_KIB = 64 * 1024
FD_MARGIN = 64


@dataclass(frozen=True, slots=True)
class Found:
    invariant: str
    at: float
    detail: str
    position: int


class Records:
    def __init__(self, facts: DeviceFacts) -> None:
        self.facts = facts
        self.line = NoisyLine(seed=0)
        self.inbox: collections.deque[tuple[float, str, bytes, bool]] = collections.deque()
        self.sent: dict[int, Sent] = {}
        self.awaiting: dict[tuple[str, bytes], list[int]] = {}
        self.written: list[Written] = []
        self.published: list[Published] = []
        self.counters: list[Published] = []
        self.availability: list[Availability] = []
        self.resets: list[Resets] = []
        self.silences: list[list[object]] = []  # [device, start, end]
        self.command_registers: dict[tuple[int, int], tuple[str, str]] = {}  # s16 registers
        self.held_up: list[list[float]] = []  # [start, end] of broker outages and stalls
        self.history: dict[tuple[str, str], list[tuple[float, object]]] = collections.defaultdict(
            list
        )
        self.warnings: list[float] = []
        self.warning_messages: collections.Counter[str] = collections.Counter()
        self.samples: list[Sample] = []
        self.counts: collections.Counter[str] = collections.Counter()
        self.violations: list[Found] = []
        self.log_offsets: dict[Path, int] = {}
        self.health: dict[str, object] = {}
        self.process: list[tuple[float, int, int]] = []  # health's (at, tasks, outbox)
        self.next_sample = 0.0
        self._seen: set[tuple[str, float, str]] = set()
        self._writes_read = {"tcp": 0, "rs485": 0}
        self._units = {unit: device for device, unit in facts.unit.items()}

    # --- recording ----------------------------------------------------------------------

    def receive(self, at: float, topic: str, payload: bytes, retain: bool) -> None:
        self.inbox.append((at, topic, payload, retain))

    def command(self, sent: Sent, topic: str, payload: bytes) -> None:
        self.sent[sent.ident] = sent
        self.awaiting.setdefault((topic, payload), []).append(sent.ident)

    def digest(self, simulators: dict[str, Simulator], now: float) -> None:
        while self.inbox:
            self._message(*self.inbox.popleft())
        start_of_new = len(self.written)
        for bus, simulator in simulators.items():
            start = self._writes_read[bus]
            for (unit, write), at in zip(
                simulator.writes[start:], simulator.write_times[start:], strict=True
            ):
                self.written.append(Written(at, unit, write.address, write.values))
            self._writes_read[bus] = len(simulator.writes)
        self._written_values(start_of_new)
        for device, keys in self.facts.watched.items():
            simulator = simulators["tcp" if device == "pump" else "rs485"]
            for key in keys:
                value = simulator.value(self.facts.unit[device], key)
                history = self.history[(device, key)]
                if not history or history[-1][1] != value:
                    history.append((now, value))

    def _written_values(self, start: int) -> None:
        """A command register's history from the write log itself: two commands to one
        register within a sampling step would leave no trace of the first otherwise."""
        for write in sorted(self.written[start:], key=lambda w: w.at):
            name = self.command_registers.get((write.unit, write.address))
            if name is not None:
                word = write.values[0]
                self.history[name].append((write.at, word - 0x10000 if word & 0x8000 else word))

    def _message(self, at: float, topic: str, payload: bytes, retain: bool) -> None:
        parts = topic.split("/")
        if topic.endswith("/set") and not retain:
            for ident in self.awaiting.pop((topic, payload), []):
                self.sent[ident] = replace(self.sent[ident], arrived=at)
        elif parts[0] == "homeassistant":
            self.counts["discovery configs received"] += 1
        elif len(parts) == 2 and parts[1] in self.facts.unit and payload:
            self._document(at, parts[1], json.loads(payload))
        elif len(parts) == 3 and parts[2] == "availability" and parts[1] in self.facts.unit:
            self.availability.append(Availability(at, parts[1], payload == b"online"))
        elif topic == f"{BASE}/bridge/health" and payload:
            self._health(at, json.loads(payload))
        elif topic.startswith(f"{BASE}/bridge/response/mapping/reload"):
            answer = json.loads(payload)
            self.counts[f"mapping reloads answered {answer.get('status')}"] += 1
            if answer.get("status") != "ok":
                self.found(Violation("mapping reload failed", at, str(answer.get("error"))))

    def _document(self, at: float, device: str, document: dict[str, object]) -> None:
        self.counts["device documents received"] += 1
        for key in self.facts.watched[device]:
            if key in document:
                self.published.append(Published(at, device, key, document[key]))
        for key in self.facts.counters[device]:
            if key in document:
                self.counters.append(Published(at, device, key, document[key]))

    def _health(self, at: float, health: dict[str, object]) -> None:
        self.health = health
        process = health.get("process")
        if isinstance(process, dict):
            self.process.append((at, int(process["tasks"]), int(process["outbox"])))
        devices = health.get("devices", {})
        assert isinstance(devices, dict)
        for device, figures in devices.items():
            self.resets.append(Resets(at, device, figures.get("counter_resets", 0)))

    def read_log(self, log: Path, now: float) -> None:
        with log.open("rb") as file:
            file.seek(self.log_offsets[log])
            data = file.read()
        end = data.rfind(b"\n") + 1
        self.log_offsets[log] += end
        for line in data[:end].splitlines():
            try:
                record = json.loads(line)
            except ValueError:
                self.counts["log lines not JSON"] += 1
                continue
            self.counts[f"log lines {record.get('level')}"] += 1
            if record.get("event") == "mqtt_up":
                self.counts[f"bridge MQTT sessions on {record.get('protocol')}"] += 1
            if record.get("level") in {"warning", "error", "critical"}:
                self.warnings.append(now)
                self.warning_messages[f"{record['level']}: {record.get('message', '')[:140]}"] += 1

    def sample(self, now: float, pid: int, memory: Callable[[int, str], int], every: float) -> None:
        self.next_sample = now + every
        try:
            fds = len(os.listdir(f"/proc/{pid}/fd"))
            self.samples.append(Sample(now, memory(pid, "VmRSS"), fds))
        except (FileNotFoundError, ProcessLookupError):
            return

    def silent(self, device: str, now: float) -> list[object]:
        silence: list[object] = [device, now, math.inf]
        self.silences.append(silence)
        return silence

    def exited(self, now: float, code: int, position: int) -> None:
        self.counts["bridge restarts after an exit"] += 1
        self._keep(Found("bridge process exited", now, f"exit code {code}", position))

    # --- checking -----------------------------------------------------------------------

    def found(self, violation: Violation, position: int = -2) -> None:
        self._keep(Found(violation.invariant, violation.at, violation.detail, position))

    def check(self, now: float, position_at: Callable[[float], int], final: bool = False) -> None:
        silences = [Silence(d, s, e) for d, s, e in self.silences]  # type: ignore[arg-type]
        found = [
            *check_commands(list(self.sent.values()), self.written),
            *check_guarded(self.written, self.facts.guarded),
            *check_counters(
                self.counters, self.resets, now, confirm_within=2 * HEALTH_INTERVAL + 5
            ),
            *check_values(
                self.published, self.history, self.facts.windows, [(s, e) for s, e in self.held_up]
            ),
            *check_availability(self.availability, silences, self.facts.thresholds, now),
            *check_log_rate(self.warnings, WARNINGS_PER_MINUTE),
            *check_bounded(self.samples, RSS_MARGIN_KIB, FD_MARGIN),
        ]
        for violation in found:
            self._keep(
                Found(
                    violation.invariant, violation.at, violation.detail, position_at(violation.at)
                )
            )
        self.counts["invariant checks run"] += 1
        if final:
            self.counts["commands checked"] = len(self.sent)
            self.counts["writes checked"] = len(self.written)
            self.counts["published values compared"] = len(self.published)
            self.counts["counter readings checked"] = len(self.counters)
            self.counts["silences checked"] = len(self.silences)

    def _keep(self, found: Found) -> None:
        key = (found.invariant, round(found.at, 3), found.detail)
        if key in self._seen:
            return
        self._seen.add(key)
        self.violations.append(found)
        print(f"VIOLATION [{found.position}] {found.invariant}: {found.detail}", flush=True)

    def health_lines(self) -> list[str]:
        """What the bridge's last health report and the line say of the run."""
        lines = [f"RS-485 replies damaged (CRC noise or torn): {self.line.damaged}"]
        buses = self.health.get("buses", {})
        devices = self.health.get("devices", {})
        assert isinstance(buses, dict)
        assert isinstance(devices, dict)
        for bus, b in buses.items():
            lines.append(
                f"bus {bus}: {b['requests']} requests, {b['timeouts']} timeouts, "
                f"{b['frame_errors']} frame errors, {b['reopenings']} reopenings"
            )
        keys = ("writes_done", "writes_rejected", "writes_failed", "writes_expired")
        keys += ("counter_readings_held", "counter_resets")
        for device, d in devices.items():
            figures = ", ".join(f"{k} {d.get(k)}" for k in keys if d.get(k))
            lines.append(f"{device}: {d['requests']} requests, {d['errors']} errors; {figures}")
        return [f"- {line}" for line in lines]

    def resource_lines(self) -> list[str]:
        if not self.samples:
            return ["no process samples"]
        settled = self.samples[len(self.samples) // 5 :]
        rss = [(s.at, s.rss_kib / 1024) for s in settled]
        fds = [(s.at, float(s.fds)) for s in settled]
        messages = self.health.get("messages", {})
        dropped = messages.get("dropped") if isinstance(messages, dict) else None
        return [
            f"RSS {min(r for _, r in rss):.1f}-{max(r for _, r in rss):.1f} MiB, slope "
            f"{slope_per_hour(rss):+.2f} MiB/h; open fds {min(f for _, f in fds):.0f}-"
            f"{max(f for _, f in fds):.0f}, slope {slope_per_hour(fds):+.1f}/h "
            f"(after the first fifth; {len(self.samples)} samples)",
            f"outbox: bounded by its deque; messages it dropped (last health): {dropped}",
            *self._process_lines(),
        ]

    def _process_lines(self) -> list[str]:
        """The asyncio tasks and the outbox as the health reports said them."""
        settled = self.process[len(self.process) // 5 :]
        if not settled:
            return ["asyncio tasks and outbox: no health report with them"]
        tasks = [(at, float(t)) for at, t, _ in settled]
        outbox = [(at, float(o)) for at, _, o in settled]
        return [
            f"asyncio tasks {min(t for _, t in tasks):.0f}-{max(t for _, t in tasks):.0f}, "
            f"slope {slope_per_hour(tasks):+.1f}/h; outbox {min(o for _, o in outbox):.0f}-"
            f"{max(o for _, o in outbox):.0f} messages, slope {slope_per_hour(outbox):+.1f}/h "
            f"(health reports after the first fifth: {len(settled)})"
        ]
