"""Community Home Assistant modbus packages the import is tested against, pinned by commit.

Their files are not ours and are not committed here: a test reads each one from a local
mirror of its repository (``git --git-dir <mirror> show <commit>:<path>``, the mirrors
under ``$BRIDGE_COMMUNITY_MIRRORS``, default ``/work/.mirror/<owner>+<name>/repo``) and
is skipped, naming the repository and commit, where the mirror or the commit is absent.

``dropped`` lists, per package, the entities the import may leave out and why (words of
the note that says so): only what the mapping model cannot express. Anything else left
out fails the test.
"""

from __future__ import annotations

import os
import re
import subprocess
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import pytest

MIRRORS = Path(os.environ.get("BRIDGE_COMMUNITY_MIRRORS", "/work/.mirror"))
_SECRET = re.compile(r"!secret\s+([A-Za-z0-9_.-]+)")


@dataclass(frozen=True, slots=True)
class Package:
    """One community package: where it is, why it was chosen, what it exercises."""

    repo: str
    commit: str
    path: str
    why: str
    exercises: str
    entities: Mapping[str, int]  # modbus entities by platform, as the file has them
    dropped: Mapping[str, str] = field(default_factory=dict)  # name -> words of its note
    placeholders: tuple[tuple[str, str], ...] = ()  # what its README asks a user to fill in

    @property
    def id(self) -> str:
        return self.repo.split("/")[1]

    @property
    def git_dir(self) -> Path:
        return MIRRORS / self.repo.replace("/", "+") / "repo"

    def write(self, folder: Path) -> Path:
        """The package file at its commit in ``folder``, placeholders filled in, with a
        ``secrets.yaml`` of dummy values for each ``!secret`` it names; skip when the
        mirror or the commit is not here."""
        where = f"{self.repo}@{self.commit}:{self.path}"
        if not self.git_dir.is_dir():
            pytest.skip(f"no mirror of {self.repo} at {self.git_dir} (wanted {where})")
        shown = subprocess.run(
            ["git", "--git-dir", str(self.git_dir), "show", f"{self.commit}:{self.path}"],
            capture_output=True,
            text=True,
            check=False,
        )
        if shown.returncode != 0:
            pytest.skip(f"{where} is not in the mirror {self.git_dir}: {shown.stderr.strip()}")
        text = shown.stdout
        for old, new in self.placeholders:
            assert old in text, f"{where}: no {old!r} to fill in"
            text = text.replace(old, new)
        path = folder / Path(self.path).name
        path.write_text(text, encoding="utf-8")
        secrets = sorted(set(_SECRET.findall(text)))
        (folder / "secrets.yaml").write_text(
            "".join(f"{name}: {_dummy(name)}\n" for name in secrets), encoding="utf-8"
        )
        return path


def _dummy(secret: str) -> str:
    """A value of the kind a secret's name asks for: a documentation address for a host,
    502 for a port, 1 for a unit, a wait or a power."""
    if "host" in secret or secret.endswith("_ip"):
        return "192.0.2.10"
    return "502" if "port" in secret else "1"


PACKAGES = (
    Package(
        repo="mkaiser/Sungrow-SHx-Inverter-Modbus-Home-Assistant",
        commit="63beec6770e8275670cdf01437cb305817f32988",
        path="modbus_sungrow.yaml",
        why="the best known community package for a hybrid inverter (Sungrow SHx), the one "
        "issue 35 was found with",
        exercises="99 sensors and 3 switches, each switch on a register a raw sensor reads; "
        "scan_interval 5, 10, 60 and 600 s through anchors; !secret host, port, wait and "
        "unit; hub delay, verify delay; sensor:, template:, automation: and scene: beside "
        "modbus:",
        entities={"sensors": 99, "switches": 3},
    ),
    Package(
        repo="WargamingPlayer/HA-Marstek-Venus-E-Modbus",
        commit="81c84d5fbe08df98981e834451bf9dd2ef0117ce",
        path="ElfinEW11B/packages/marstek_venus_battery_1_control.yaml",
        why="a home battery (Marstek Venus E) through an RS485 gateway, as a Home Assistant "
        "package with its own controls",
        exercises="55 sensors and 3 switches (restart, factory reset, backup) with verify "
        "delays; text in custom '>Ns' structures; structures of several values; "
        "signal_strength in dBm; scan_interval 5, 10, 30 and 300 s; input_*, script:, "
        "automation:, template:, utility_meter: beside modbus:",
        entities={"sensors": 55, "switches": 3},
        dropped=dict.fromkeys(
            (
                "Marstek 1 Battery Charge Limits",
                "Marstek 1 Alarm State",
                "Marstek 1 Fault State",
                *(f"Marstek 1 Manual Schedule {n}" for n in range(1, 7)),
                "Marstek 1 Capacity and Power registers",
            ),
            ".structure:",
        ),
        placeholders=(("host: [YourIPGoesHere]", "host: 192.0.2.11"),),
    ),
    Package(
        repo="nilbogAus/SMAmodbusYaml",
        commit="cc5b1d364621d5f4be2eb7585048d4f2467be884",
        path="modbus.yaml",
        why="a grid inverter (SMA Sunny Boy / Tripower) written as a bare list of hubs for "
        "`modbus: !include modbus.yaml`",
        exercises="69 sensors on 32-bit register pairs, many `<<:` merge keys per sensor; "
        "scan_interval 0 (once), 15 (the default), 60, 3600, 86400 and 604800 s; uint64 "
        "counters; two sensors of different types on one register pair; an energy "
        "device class without a state class; 'VAr'; a second sensor of one name",
        entities={"sensors": 69},
        dropped={"SMA Nominal power in Ok Mode": "Home Assistant loads the first only"},
    ),
)
