"""bridge.config.store on disk: numbered backups rotate, a crash before the rename leaves
the file as it was, a disk that refuses leaves no temp file; secrets never in a view, a
summary or a conflict diff, and kept when an edit leaves them out; a config that is no
file is read-only; links, CRLF lines, YAML 1.1 words and threads."""

from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import pytest

from bridge.config import load_config, load_config_data
from bridge.config.edits import SECRET_MARK, parse_change
from bridge.config.store import BACKUPS, GENERATED, ConfigStore
from bridge.errors import ConfigConflictError, ConfigReadOnlyError, ConfigWriteError

ROOT = Path(__file__).parents[2]


@pytest.fixture
def config(tmp_path: Path) -> Path:
    path = tmp_path / "config.yaml"
    shutil.copyfile(ROOT / "examples" / "rtu-serial.yaml", path)
    return path


def rename(name: str) -> Any:
    return parse_change({"kind": "edit_device", "id": "borehole_pump", "set": {"name": name}})


def temp_files(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if p.name.endswith(".tmp")]


def test_backups_rotate_newest_first_with_the_files_mode(config: Path) -> None:
    config.chmod(0o640)
    store = ConfigStore.open(config)
    versions = [config.read_bytes()]
    for number in range(BACKUPS + 2):
        store.apply(rename(f"Pump {number}"))
        versions.append(config.read_bytes())
    for number in range(1, BACKUPS + 1):
        backup = config.with_name(f"config.yaml.{number}")
        assert backup.read_bytes() == versions[-1 - number]
        assert stat.S_IMODE(backup.stat().st_mode) == 0o640
    assert not config.with_name(f"config.yaml.{BACKUPS + 1}").exists()
    assert stat.S_IMODE(config.stat().st_mode) == 0o640
    assert temp_files(config.parent) == []


CRASH = """
import os, sys
from pathlib import Path
from bridge.config.edits import parse_change
from bridge.config.store import ConfigStore

target = sys.argv[1]
store = ConfigStore.open(Path(target))
real = os.replace

def power_cut(source, destination):
    if str(destination) == target:
        os._exit(9)  # the machine stops after the temp file is on disk, before the rename
    real(source, destination)

os.replace = power_cut
store.apply(parse_change({"kind": "remove_device", "id": "borehole_pump"}))
"""


def test_a_crash_between_the_temp_file_and_the_rename_leaves_the_file(config: Path) -> None:
    before = config.read_bytes()
    done = subprocess.run(
        [sys.executable, "-c", CRASH, str(config)], cwd=ROOT, capture_output=True, check=False
    )
    assert done.returncode == 9, done.stderr.decode()
    assert config.read_bytes() == before
    assert load_config(config).config.devices[0].id == "borehole_pump"
    assert config.with_name("config.yaml.1").read_bytes() == before
    ConfigStore.open(config).apply(rename("After the crash"))  # the next edit goes through
    assert "    name: After the crash\n" in config.read_text(encoding="utf-8")


def test_a_disk_that_refuses_leaves_the_file_and_no_temp_file(config: Path) -> None:
    before = config.read_bytes()
    for number in (BACKUPS - 1, BACKUPS):  # backups that cannot move: folders in the way
        folder = config.with_name(f"config.yaml.{number}")
        folder.mkdir()
        (folder / "keep").write_text("x", encoding="utf-8")
    with pytest.raises(ConfigWriteError) as refused:
        ConfigStore.open(config).apply(rename("Never written"))
    assert "cannot replace" in refused.value.message
    assert config.read_bytes() == before
    assert temp_files(config.parent) == []


PASSWORD, TOKEN, BROKER = "60417", "a-web-token-of-32-characters-ok", "s3cret-broker-pw"


@pytest.fixture
def secret_config(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("DRIVE_PASSWORD", PASSWORD)
    path = tmp_path / "config.yaml"
    path.write_text(
        f"""# a site with every kind of secret
mqtt:
  url: mqtt://bridge:{BROKER}@127.0.0.1:1883   # the broker's login in the URL
bridge:
  web: {{token: {TOKEN}}}
buses:
  - {{id: gw, transport: tcp, host: 127.0.0.1}}
devices:
  - id: drive
    bus: gw
    unit: 1
    mapping: p2_vfd
    password: "{PASSWORD}"   # the drive's user password
  - id: fan
    bus: gw
    unit: 2
    mapping: p2_vfd
    password_env: DRIVE_PASSWORD
""",
        encoding="utf-8",
    )
    return path


def test_no_view_shows_a_secret(secret_config: Path) -> None:
    view = ConfigStore.open(secret_config).public_view()
    shown = json.dumps(view)
    for secret in (PASSWORD, TOKEN, BROKER, "DRIVE_PASSWORD"):
        assert secret not in shown
    assert view["devices"][0]["password"] == SECRET_MARK
    assert view["devices"][1]["password_env"] == SECRET_MARK
    assert view["bridge"]["web"]["token"] == SECRET_MARK
    assert view["mqtt"]["url"] == f"mqtt://bridge:{SECRET_MARK}@127.0.0.1:1883"
    assert view["devices"][0]["mapping"] == "p2_vfd"


def test_secrets_left_out_or_given_as_the_mark_are_kept(secret_config: Path) -> None:
    before = secret_config.read_text(encoding="utf-8")
    store = ConfigStore.open(secret_config)
    edit = {"kind": "edit_device", "id": "drive", "set": {"unit": 3, "password": SECRET_MARK}}
    applied = store.apply(parse_change(edit))
    assert secret_config.read_text(encoding="utf-8") == before.replace(
        "    unit: 1\n", "    unit: 3\n"
    )
    assert applied.loaded.config.devices[0].password_value() == PASSWORD
    applied = store.apply(parse_change({"kind": "edit_device", "id": "fan", "set": {"unit": 4}}))
    after = secret_config.read_text(encoding="utf-8")
    assert "    password_env: DRIVE_PASSWORD\n" in after  # the variable, never its value
    assert after.count(PASSWORD) == 1  # the drive's own, as the user wrote it
    assert applied.loaded.config.devices[1].password_value() == PASSWORD


def test_a_new_secret_is_written_but_never_summarised(secret_config: Path) -> None:
    edit = {"kind": "edit_device", "id": "drive", "set": {"password": "12345"}}
    applied = ConfigStore.open(secret_config).apply(parse_change(edit))
    assert 'password: "12345"   # the drive' in secret_config.read_text(encoding="utf-8")
    assert "12345" not in applied.summary
    assert f"  devices.drive.password: {json.dumps(SECRET_MARK)} (changed)" in applied.summary


def test_a_conflict_diff_hides_secrets(secret_config: Path) -> None:
    store = ConfigStore.open(secret_config)
    text = secret_config.read_text(encoding="utf-8")
    secret_config.write_text(
        text.replace(PASSWORD, "55555").replace(BROKER, "n3w-pw"), encoding="utf-8"
    )
    with pytest.raises(ConfigConflictError) as conflict:
        store.apply(parse_change({"kind": "remove_device", "id": "fan"}))
    for secret in (PASSWORD, "55555", BROKER, "n3w-pw", TOKEN):
        assert secret not in conflict.value.diff
    assert f"    password: {SECRET_MARK}   # the drive" in conflict.value.diff


def test_a_config_that_is_no_file_is_read_only(tmp_path: Path) -> None:
    data = {
        "mqtt": {"password": BROKER},
        "buses": [{"id": "gw", "transport": "tcp", "host": "127.0.0.1"}],
        "devices": [{"id": "pump", "bus": "gw", "unit": 1, "mapping": "p2_vfd"}],
    }
    loaded = load_config_data(data, tmp_path / "config.yaml")
    store = ConfigStore.read_only(loaded, "the add-on's options")
    assert not store.writable
    for call in (store.apply, store.preview):
        with pytest.raises(ConfigReadOnlyError, match="the add-on's options"):
            call(rename("x"))
    view = store.public_view()
    assert BROKER not in json.dumps(view)
    assert view["devices"][0]["id"] == "pump"
    assert list(tmp_path.iterdir()) == []


def test_a_generated_file_is_read_only(config: Path) -> None:
    text = config.read_text(encoding="utf-8")
    config.write_text(
        f"{GENERATED}the add-on's options (/data/options.json)\n{text}", encoding="utf-8"
    )
    before = config.read_bytes()
    store = ConfigStore.open(config)
    assert not store.writable
    with pytest.raises(ConfigReadOnlyError) as refused:
        store.apply(rename("x"))
    assert "generated from the add-on's options (/data/options.json)" in refused.value.message
    assert store.public_view()["devices"][0]["id"] == "borehole_pump"
    assert config.read_bytes() == before
    assert sorted(os.listdir(config.parent)) == ["config.yaml"]


def test_a_linked_config_is_written_where_the_link_leads(config: Path) -> None:
    real = config.parent / "real" / "bridge.yaml"
    real.parent.mkdir()
    config.rename(real)
    config.symlink_to(real)
    ConfigStore.open(config).apply(rename("Linked"))
    assert config.is_symlink()
    assert "    name: Linked\n" in real.read_text(encoding="utf-8")
    assert real.with_name("bridge.yaml.1").exists()


def test_crlf_lines_stay_crlf(config: Path) -> None:
    config.write_bytes(config.read_bytes().replace(b"\n", b"\r\n"))
    before = config.read_bytes()
    ConfigStore.open(config).apply(rename("Windows"))
    assert config.read_bytes() == before.replace(b"name: Borehole pump\r\n", b"name: Windows\r\n")


@pytest.mark.parametrize(
    "name",
    [
        "on",
        "yes",
        "No",
        "0755",
        "12:30",
        "null",
        "~",
        "1e3",
        "true",
        "- x",
        "a: b",
        "!!python/object:os.system",
        "*x",
        "&a",
        "{a: 1}",
        "[1]",
        "'q'",
        '"dq"',
        "#hash",
        "a #b",
        "%TAG",
        " lead",
        "trail ",
        "\\",
    ],
)
def test_a_name_yaml_would_read_as_something_else_is_written_quoted(
    config: Path, name: str
) -> None:
    applied = ConfigStore.open(config).apply(rename(name))
    assert applied.loaded.config.devices[0].name == name
    assert load_config(config).config.devices[0].name == name


def test_edits_from_threads_are_made_one_at_a_time(config: Path) -> None:
    store = ConfigStore.open(config)
    edits = [
        {"id": "borehole_pump", "set": {"name": "Pump"}},
        {"id": "borehole_pump", "set": {"poll.slow": "300s"}},
        {"id": "booster_starter", "set": {"name": "Starter"}},
        {"id": "booster_starter", "set": {"enabled": False}},
    ]
    threads = [
        threading.Thread(target=store.apply, args=(parse_change({"kind": "edit_device", **e}),))
        for e in edits
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    pump, starter = load_config(config).config.devices
    assert (pump.name, pump.poll.slow, starter.name, starter.enabled) == (
        "Pump",
        300,
        "Starter",
        False,
    )
    assert sorted(os.listdir(config.parent)) == ["config.yaml"] + [
        f"config.yaml.{n}" for n in range(1, 5)
    ]
