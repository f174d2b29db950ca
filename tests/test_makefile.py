"""`make demo` installs what the demo needs, `make test` the whole toolchain (make -n: the
commands are printed, not run)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")


def planned(target: str, venv: Path) -> list[str]:
    outer = ("MAKEFLAGS", "MAKELEVEL", "MFLAGS", "MAKEOVERRIDES")  # when make test runs us
    result = subprocess.run(
        ["make", "--no-print-directory", "-n", target, f"VENV={venv}"],
        capture_output=True,
        text=True,
        timeout=30,
        check=True,
        cwd=ROOT,
        env={k: v for k, v in os.environ.items() if k not in outer},
    )
    return result.stdout.splitlines()


def test_make_demo_installs_the_runtime_and_the_demo_extra_only(tmp_path: Path) -> None:
    """Not the dev tools (ruff, mypy, pytest: three times the size) and not editable (the
    editable install makes setuptools warn about folders named like the package)."""
    venv = tmp_path / "venv"
    lines = planned("demo", venv)
    installs = [line for line in lines if " install " in line and "--upgrade pip" not in line]
    assert installs == [f"{venv}/bin/pip install --quiet '.[demo]'"]
    assert lines[-1] == f"{venv}/bin/modbus-mqtt-bridge demo "


def test_make_test_installs_the_dev_toolchain_editable(tmp_path: Path) -> None:
    venv = tmp_path / "venv"
    lines = planned("test", venv)
    assert f"{venv}/bin/pip install --quiet -e '.[dev]'" in lines
    assert lines[-1] == f"{venv}/bin/pytest -n 4 --dist loadfile"


def test_make_demo_uses_a_dev_venv_as_it_is(tmp_path: Path) -> None:
    """After `make test`, `make demo` runs the editable install: no second install."""
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    (venv / "bin" / "python").touch()
    stamp = next(line for line in planned("test", venv) if "touch" in line).split()[-1]
    Path(stamp).touch()
    assert planned("demo", venv) == [f"{venv}/bin/modbus-mqtt-bridge demo "]
