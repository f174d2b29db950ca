"""The README's config and mapping examples stay valid."""

from __future__ import annotations

import re
from pathlib import Path

from bridge.config import Config
from bridge.core.codec import decode
from bridge.core.entity import Table
from bridge.core.mapping import parse_mapping
from bridge.core.yaml_source import parse_yaml

README = (Path(__file__).resolve().parent.parent / "README.md").read_text()
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
