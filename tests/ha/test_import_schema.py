"""Every Home Assistant modbus config the tests import, validated by Home Assistant's own
schema (``homeassistant.components.modbus.CONFIG_SCHEMA``, run by the chroot's Python of
the version under test): each config it accepts converts with each entity accounted for,
converted (a mapping entity of that name) or named in the report.

The configs: Home Assistant's fixtures (tests/components/modbus/fixtures), its sensor
decode table (test_sensor.py, see tests/importer/data/ha_sensor_values.yaml), the configs
of its test_binary_sensor, test_switch, test_fan, test_light, test_climate, test_cover and
test_init (tests/importer/data/ha_tests/), and this project's whole-configuration,
every-key and shaping examples (tests/importer/test_ha_modbus.py).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Any

import yaml

from bridge.importer.ha_modbus import import_ha
from bridge.importer.source import load_source
from tests.ha.conftest import installed_home_assistant
from tests.ha.homeassistant import CLEAN_ENV
from tests.importer.test_ha_modbus import CASES, DATA, EVERY_KEY, SHAPED, WHOLE, hub_with
from tests.importer.test_ha_tests import configs as ha_test_configs
from tests.importer.test_ha_tests import hub_of

SCRIPT = """\
import json, pathlib, sys
from homeassistant.components.modbus import CONFIG_SCHEMA  # first: 2026.x swaps voluptuous
from homeassistant.util.yaml import load_yaml
import voluptuous as vol
KINDS = ("sensors", "binary_sensors", "switches", "climates", "covers", "fans", "lights")
answer = {}
for path in sorted(pathlib.Path(sys.argv[1]).glob("*.yaml")):
    try:
        valid = CONFIG_SCHEMA({"modbus": load_yaml(str(path))["modbus"]})
    except vol.Invalid as exc:
        answer[path.name] = {"refused": str(exc)}
        continue
    answer[path.name] = {"entities": [
        [kind, entity["name"]] for hub in valid["modbus"] for kind in KINDS
        for entity in hub.get(kind, [])
    ]}
print(json.dumps(answer))
"""


def configs() -> dict[str, str]:
    texts = {f"fixture_{p.name}": p.read_text() for p in (DATA / "ha_fixtures").glob("*.yaml")}
    texts |= {"whole.yaml": WHOLE, "every_key.yaml": EVERY_KEY, "shaped.yaml": SHAPED}
    valid = [line for line in SHAPED.splitlines() if "zero_suppress: -1" not in line]
    texts["shaped_valid.yaml"] = "\n".join(valid) + "\n"  # HA refuses a negative one
    for test, config in ha_test_configs():
        name = test.replace("::", "-").replace("[", "_").replace("]", "")
        texts[f"{name}.yaml"] = yaml.safe_dump({"modbus": [hub_of(config)]}, sort_keys=False)
    current = [
        line for line in EVERY_KEY.splitlines() if "retries" not in line and "lazy" not in line
    ]
    texts["every_key_current.yaml"] = "\n".join(current) + "\n"  # without the keys HA dropped
    for n, case in enumerate(CASES):
        sensor = {"name": "Test", "address": 51, "slave": 1, "scan_interval": 1} | case["addon"]
        texts[f"sensor_case_{n:02}.yaml"] = hub_with(sensor)
    return texts


def home_assistants_verdict(root: Path, version: str, folder: Path) -> dict[str, Any]:
    inside = "/" + str(folder.relative_to(root))
    python = f"/opt/ha-{version}/bin/python"
    answer = subprocess.run(
        ["chroot", str(root), *CLEAN_ENV, python, f"{inside}/schema.py", inside],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert answer.returncode == 0, answer.stderr[-3000:]
    return dict(json.loads(answer.stdout.splitlines()[-1]))


def test_every_config_home_assistant_accepts_converts_with_each_entity_accounted_for() -> None:
    root, version = installed_home_assistant()
    (root / "tmp").mkdir(exist_ok=True)
    folder = Path(tempfile.mkdtemp(prefix="import-schema-", dir=root / "tmp"))
    try:
        (folder / "schema.py").write_text(SCRIPT)
        texts = configs()
        for name, text in texts.items():
            (folder / name).write_text(text)
        verdict = home_assistants_verdict(root, version, folder)
        accepted = {name: v["entities"] for name, v in verdict.items() if "entities" in v}
        for name, entities in accepted.items():
            result = import_ha(load_source(folder / name), name)
            converted = {
                entity["name"]
                for device in result.devices
                for entity in device.mapping["entities"].values()
            }
            noted = [note.key for note in result.notes]
            for kind, entity in entities:
                assert entity in converted or any(
                    key == entity or key.startswith(f"{entity}.") or key.startswith(f"{entity} ")
                    for key in noted
                ), f"{name}: {kind} {entity!r} neither converted nor reported: {noted}"
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    refused = sorted(set(texts) - set(accepted))
    print(
        f"Home Assistant {version}: {len(accepted)} configs accepted and converted, refused: "
        + ", ".join(f"{n} ({verdict[n]['refused'][:80]})" for n in refused)
    )
    assert {"whole.yaml", "fixture_configuration.yaml", "fixture_configuration_2.yaml"} <= set(
        accepted
    )
    tests = {name for name in texts if name.startswith("test_")}
    gone = {f"test_cover-test_config_cover_{n}.yaml" for n in (1, 2)}  # lazy_error_count
    assert set(refused) & tests == {n for n in tests if "exception_struct" in n} | gone
    assert "shaped_valid.yaml" in accepted  # min_value/max_value/zero_suppress, switch words
