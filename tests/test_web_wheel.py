"""The web page ships inside the wheel: its static files are package data, not a build step."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
STATIC = ROOT / "bridge" / "web" / "static"


def test_the_wheel_carries_every_static_file_of_the_page(tmp_path: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp_path), str(ROOT)],
        check=True,
        capture_output=True,
        timeout=50,
    )
    (wheel,) = tmp_path.glob("modbus_mqtt_bridge-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    shipped = {f"bridge/web/static/{path.name}" for path in STATIC.iterdir() if path.is_file()}
    assert shipped == {
        "bridge/web/static/index.html",
        "bridge/web/static/app.js",
        "bridge/web/static/add.js",
        "bridge/web/static/edit.js",
        "bridge/web/static/entity.js",
        "bridge/web/static/style.css",
    }
    assert shipped <= names
    assert {"bridge/web/__init__.py", "bridge/web/server.py"} <= names


def test_the_page_asks_nothing_of_other_sites() -> None:
    """No CDN, no web fonts, no framework: every URL in the page is relative."""
    for path in STATIC.iterdir():
        text = path.read_text(encoding="utf-8")
        for marker in ("http://", "https://", "//cdn", "@import", "@font-face", "url("):
            assert marker not in text, (path.name, marker)
