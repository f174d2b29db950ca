"""The three bridges of ``bench/peers.py``: how each is installed, started, commanded and read.

A peer lives in its own venv under ``bench/.peers/<name>`` (git ignores it), created with
this interpreter's ``venv`` and ``pip install`` of its requirements; the venv is reused
while ``requirements.txt`` inside it lists the same ones.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from peer_configs import (
    COMMAND_KEY,
    DEVICES,
    KEYS,
    M2_PREFIX,
    M4_PREFIX,
    UNIT,
    modbus2mqtt_topics,
    registers,
)

PEERS_DIR = Path(__file__).resolve().parent / ".peers"
BRIDGE = Path(sys.executable).with_name("modbus-mqtt-bridge")
WORDS = {"on": True, "true": True, "1": True, "off": False, "false": False, "0": False}


def truth(value: object) -> bool | None:
    """A switch value as any of the three publishes it (``true``, ``"ON"``, ``"1"``...)."""
    if isinstance(value, bool):
        return value
    if isinstance(value, bytes):
        value = value.decode(errors="replace")
    return WORDS.get(str(value).strip().lower())


@dataclass(frozen=True)
class Run:
    """Where one run's bridge connects: its config files, the broker, the device."""

    paths: dict[str, Path]
    mqtt_port: int
    modbus_port: int
    units: list[int]


class Kind:
    """One bridge under test."""

    name = ""
    title = ""
    script = ""
    requirements: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    command_name = COMMAND_KEY

    def prepare(self) -> None:
        """Install the peer in its venv unless it is there already."""
        if not self.requirements:
            return
        folder = PEERS_DIR / self.name
        wanted = "\n".join(self.requirements) + "\n"
        marker = folder / "requirements.txt"
        if marker.exists() and marker.read_text() == wanted and self.executable().exists():
            return
        print(f"installing {' '.join(self.requirements)} in {folder}", file=sys.stderr)
        shutil.rmtree(folder, ignore_errors=True)
        subprocess.run([sys.executable, "-m", "venv", str(folder)], check=True)  # noqa: S603
        pip = [str(folder / "bin" / "pip"), "install", "--quiet", *self.requirements]
        done = subprocess.run(pip, capture_output=True, text=True, check=False)  # noqa: S603
        if done.returncode:
            raise RuntimeError(f"{' '.join(pip)} failed:\n{done.stdout}{done.stderr}")
        marker.write_text(wanted)

    def executable(self) -> Path:
        return PEERS_DIR / self.name / "bin" / self.script

    def argv(self, run: Run) -> list[list[str]]:
        """The command line of each process."""
        raise NotImplementedError

    def read(self, topic: str, payload: bytes) -> dict[str, object]:
        """The values of unit 1 a message carries, by topic name."""
        raise NotImplementedError

    def parts(self, key: str) -> set[str]:
        """The topic names that together carry the value ``key``."""
        return {key}

    def complete(self, names: set[str]) -> int:
        """How many of the values arrived whole among ``names``."""
        return sum(self.parts(key) <= names for key in KEYS)

    def command(self, on: bool) -> tuple[str, str]:
        """Topic and payload switching the pump on or off."""
        raise NotImplementedError


class ThisBridge(Kind):
    name = "bridge"
    title = "this bridge"
    notes = ("defaults: MQTT 5, QoS 1, retained compact JSON state, discovery",)
    config = "bridge"

    def argv(self, run: Run) -> list[list[str]]:
        config = str(run.paths[self.config])
        return [[str(BRIDGE), "run", "-c", config, "--log-level", "warning"]]

    def read(self, topic: str, payload: bytes) -> dict[str, object]:
        device = f"modbus/{DEVICES[UNIT]}"
        if topic == device:
            try:
                document = json.loads(payload)
            except ValueError:
                return {}
            return {k: v for k, v in document.items() if k in KEYS}
        key = topic.removeprefix(f"{device}/")
        return {key: payload} if key in KEYS and key != topic else {}

    def command(self, on: bool) -> tuple[str, str]:
        return f"modbus/{DEVICES[UNIT]}/{COMMAND_KEY}/set", "ON" if on else "OFF"


class ThisBridgeValues(ThisBridge):
    """The same, publishing what the peers publish: a plain topic per changed value."""

    name = "bridge-values"
    title = "this bridge, output: values"
    notes = ("mqtt.output: values (plain per-key topics only), discovery: off",)
    config = "bridge-values"


class Modbus4mqtt(Kind):
    name = "modbus4mqtt"
    title = "modbus4mqtt 0.7.1"
    script = "modbus4mqtt"
    requirements = ("modbus4mqtt==0.7.1",)
    notes = (
        "one device per config and process",
        "scan_batching 1 (the device refuses longer reads): 50 ms pause after every read",
        "publishes changed values only (pub_only_on_change), QoS 0, not retained",
    )

    def argv(self, run: Run) -> list[list[str]]:
        return [
            [
                *(str(self.executable()), "--hostname", "127.0.0.1", "--port", str(run.mqtt_port)),
                *("--config", str(run.paths[f"modbus4mqtt-{unit}"])),
                *("--mqtt_topic_prefix", f"{M4_PREFIX}/{DEVICES[unit]}"),
            ]
            for unit in run.units
        ]

    def read(self, topic: str, payload: bytes) -> dict[str, object]:
        key = topic.removeprefix(f"{M4_PREFIX}/{DEVICES[UNIT]}/")
        return {key: payload} if key in KEYS and key != topic else {}

    def command(self, on: bool) -> tuple[str, str]:
        return f"{M4_PREFIX}/{DEVICES[UNIT]}/{COMMAND_KEY}/set", "ON" if on else "OFF"


class Modbus2mqtt(Kind):
    name = "modbus2mqtt"
    title = "modbus2mqtt 0.73"
    script = "modbus2mqtt"
    requirements = ("modbus2mqtt==0.73", "pymodbus==3.8.6")
    notes = (
        "one poller per register; the u32 counters as two words each (40 topics)",
        "raw numbers, no enum labels; publishes changed values only, QoS 0, retained",
        "Modbus TCP timeout: pymodbus' 3 s, 3 retries (--set-modbus-timeout is for RTU only)",
    )

    def __init__(self) -> None:
        self.topics = {r.key: {t for t, _ in modbus2mqtt_topics(r)} for r in registers()}

    def argv(self, run: Run) -> list[list[str]]:
        return [
            [
                *(str(self.executable()), "--tcp", "127.0.0.1", "--tcp-port", str(run.modbus_port)),
                *("--mqtt-host", "127.0.0.1", "--mqtt-port", str(run.mqtt_port)),
                *("--config", str(run.paths["modbus2mqtt"])),
            ]
        ]

    def read(self, topic: str, payload: bytes) -> dict[str, object]:
        name = topic.removeprefix(f"{M2_PREFIX}/{DEVICES[UNIT]}/state/")
        known = name != topic and any(name in names for names in self.topics.values())
        return {name: payload} if known else {}

    def parts(self, key: str) -> set[str]:
        return self.topics[key]

    def command(self, on: bool) -> tuple[str, str]:
        return f"{M2_PREFIX}/{DEVICES[UNIT]}/set/{COMMAND_KEY}", "1" if on else "0"


KINDS: tuple[Kind, ...] = (Modbus4mqtt(), Modbus2mqtt(), ThisBridge(), ThisBridgeValues())
