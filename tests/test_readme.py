"""The README's config and mapping examples stay valid."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from bridge.config import Config
from bridge.core.codec import decode
from bridge.core.entity import Table
from bridge.core.mapping import parse_mapping
from bridge.core.yaml_source import parse_yaml

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()
BLOCKS = re.findall(r"```yaml\n(.*?)```", README, flags=re.DOTALL)


def test_readme_config_example_is_valid() -> None:
    config = Config.model_validate(parse_yaml(BLOCKS[0], "README config"))
    assert [d.id for d in config.devices] == ["borehole_pump"]


def test_readme_mapping_example_is_valid_and_decodes() -> None:
    mapping = parse_mapping(BLOCKS[1], "README mapping")
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
