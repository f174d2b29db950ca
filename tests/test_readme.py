"""The README stays true: its config and mapping examples are valid, the output it shows is
what the commands print, and what it tells a newcomer to run works from a fresh clone."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from bridge.cli.demo import SEEDS
from bridge.config import Config, load_config
from bridge.core.codec import decode
from bridge.core.entity import Table
from bridge.core.mapping import builtin_mapping_path, load_mapping, parse_mapping
from bridge.core.yaml_source import parse_yaml

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()
BLOCKS = re.findall(r"```yaml\n(.*?)```", README, flags=re.DOTALL)
# the mapping example is the block that declares entities (the automations are YAML too)
MAPPING_BLOCK = next(block for block in BLOCKS if "\nentities:" in f"\n{block}")


def test_readme_config_example_is_valid() -> None:
    config = Config.model_validate(parse_yaml(BLOCKS[0], "README config"))
    assert [d.id for d in config.devices] == ["borehole_pump", "fan_drive"]
    assert config.devices[1].password_env == "P2_PASSWORD"


def test_readme_mapping_example_is_valid_and_decodes() -> None:
    mapping = parse_mapping(MAPPING_BLOCK, "README mapping")
    points = mapping.points()
    image = {(Table.HOLDING, 0x97): 35, (Table.HOLDING, 0x57): 0}
    assert decode(points["actual_value"], image) == 3.5
    assert points["actual_value"].address == 0x97


def shown_runs(text: str) -> list[tuple[str, str]]:
    """``$ modbus-mqtt-bridge ...`` lines of indented blocks with the output shown below."""
    runs = []
    for match in re.finditer(
        r"^    \$ (modbus-mqtt-bridge [^\n]*)\n((?:    [^$\n][^\n]*\n)+)", text, re.M
    ):
        command = match.group(1).split("  #")[0].strip()
        output = "".join(line[4:] + "\n" for line in match.group(2).splitlines())
        runs.append((command, output))
    return runs


@pytest.mark.parametrize(("command", "output"), shown_runs(README), ids=lambda v: v[:60])
def test_readme_shows_real_output(command: str, output: str) -> None:
    """Output the README shows is what the command prints, from the repository's folder."""
    args = command.split()[1:]
    result = subprocess.run(
        [sys.executable, "-m", "bridge.cli", *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        cwd=ROOT,
    )
    assert result.stdout + result.stderr == output


def test_readme_shows_the_bad_example() -> None:
    assert any(command.endswith("check -c examples/bad.yaml") for command, _ in shown_runs(README))


def test_every_example_file_is_in_the_readme() -> None:
    examples = sorted(p.name for p in (ROOT / "examples").glob("*.yaml"))
    assert "site.yaml" in examples
    for name in examples:
        assert f"(examples/{name})" in README, name


def test_the_quick_start_lists_what_a_fresh_machine_needs() -> None:
    start = README[README.index("## Quick start") : README.index("## Run it against your hardware")]
    for needed in ("python3-venv", "mosquitto-clients", "openssl", ". .venv/bin/activate"):
        assert needed in start, needed
    for option in ("--username", "--password-env", "--password-file", "--local-broker", "--keep"):
        assert option in start, option


def test_the_demo_options_the_readme_names_exist() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "bridge.cli", "demo", "--help"],
        capture_output=True,
        text=True,
        timeout=30,
        check=True,
    )
    for option in set(re.findall(r"demo\b[^`\n]*?(--[a-z-]+)", README)) | {"--local-broker"}:
        assert option in result.stdout, option


def test_the_five_device_simulate_command_is_what_examples_config_expects() -> None:
    """ "Try it without hardware": the simulate command serves every device of
    examples/config.yaml at its unit, on its bus's port."""
    section = README[README.index("## Try it without hardware") :]
    command = section[section.index("modbus-mqtt-bridge simulate --tcp") :]
    command = command[: command.index("modbus-mqtt-bridge run -c examples/config.yaml")]
    args = command.replace("\\\n", " ").split()
    served = {(args[i + 1], int(args[i + 3])) for i, arg in enumerate(args) if arg == "--mapping"}
    config = load_config(ROOT / "examples" / "config.yaml").config
    assert served == {(d.mapping, d.unit) for d in config.devices}
    (bus,) = config.buses
    assert args[args.index("--tcp") + 1] == f"{bus.host}:{bus.tcp_port}"  # type: ignore[union-attr]


def test_the_demo_fault_command_names_a_real_device_and_alarm() -> None:
    match = re.search(r"demo/fault \\\n\s+-m '(\{.*?\})'", README)
    assert match is not None
    body = json.loads(match.group(1))
    seed = next(s for s in SEEDS if s.id == body["device"])
    mapping = load_mapping(builtin_mapping_path(seed.mapping))
    assert mapping.entities[body["fault"]].alarm


def test_readme_automations_are_home_assistant_yaml_for_the_bridge_s_triggers() -> None:
    """The automation examples use the trigger and event the bridge publishes."""
    automations = [block for block in BLOCKS if block.startswith("automation:")]
    assert len(automations) == 2
    device, event = (
        parse_yaml(block, "README automation")["automation"][0] for block in automations
    )
    trigger = device["triggers"][0]
    assert (trigger["trigger"], trigger["domain"], trigger["type"]) == ("device", "mqtt", "raised")
    assert trigger["subtype"] == "Dry running"  # the name of nastec_vasco's alarm_dry_running
    assert event["triggers"][0]["entity_id"].endswith("_alarm_events")
