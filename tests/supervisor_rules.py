"""The Home Assistant Supervisor's own validation of an add-on (an "app" in its code),
loaded from the Supervisor's source at a pinned release, so the tests cannot drift from
what the Supervisor accepts.

Why loaded and not copied: the Supervisor is not on PyPI, and its code stays out of this
repository. The tests read it from a checkout at ``SUPERVISOR_COMMIT``: ``SUPERVISOR_SRC``
names a work tree (the CI workflow checks the Supervisor out there at that commit) or a
git directory holding the commit (read with ``git show``, whatever is checked out); else
``SUPERVISOR_CANDIDATES`` are tried. Without one, ``load()`` raises SupervisorMissingError and
the tests skip saying how to get it.

What runs is the Supervisor's unchanged source of the modules that define the rules:
``supervisor/apps/validate.py`` (SCHEMA_APP_CONFIG, the translations schema),
``supervisor/apps/options.py`` (AppOptions: the options against the add-on's schema, as
the Supervisor checks them before a start), and what they import from ``const``,
``validate``, ``docker`` and ``jobs``. Two things are supplied here: stand-ins for the
modules of the running Supervisor these import only for names used at run time (CoreSys,
the hardware database, aiohttp), and, on a Python before 3.14, parentheses around the
PEP 758 ``except A, B:`` clauses the source uses (the only rewrite). Its voluptuous and
awesomeversion are pinned to the Supervisor's own requirements (pyproject, test extra).
The Supervisor's advisories (a deprecated or legacy key) are logged warnings: they are
reported here as problems too.
"""

from __future__ import annotations

import logging
import os
import re
import subprocess
import sys
import types
from collections.abc import Iterator
from contextlib import contextmanager
from functools import cache
from pathlib import Path
from typing import Any

SUPERVISOR_VERSION = "2026.08.0"
SUPERVISOR_COMMIT = "0b5b0ce15f30f5881962ccb1abbac329a6556b65"
SUPERVISOR_CANDIDATES = (Path("/work/.mirror/home-assistant+supervisor/repo"),)
MODULES = (
    "const",
    "docker.const",
    "docker.utils",
    "utils.validate",
    "validate",
    "jobs.const",
    "hardware.const",
    "apps.const",
    "apps.options",
    "apps.validate",
)
PACKAGES = ("", "docker", "utils", "jobs", "hardware", "apps")
_PEP758 = re.compile(r"^(\s*except) ([\w.]+(?:, [\w.]+)+):", re.MULTILINE)


class SupervisorMissingError(Exception):
    """No checkout of the Supervisor at SUPERVISOR_COMMIT; the message says how to get one."""


def _source(root: Path, path: str) -> str:
    """The file at the pinned commit, from a work tree at it or from a git directory."""
    if (root / path).is_file() and (root / ".git").exists():
        head = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            check=False,
        ).stdout.strip()
        if head == SUPERVISOR_COMMIT:
            return (root / path).read_text(encoding="utf-8")
    shown = subprocess.run(
        ["git", "--git-dir", str(root), "show", f"{SUPERVISOR_COMMIT}:{path}"],
        capture_output=True,
        text=True,
        check=False,
    )
    if shown.returncode != 0:
        shown = subprocess.run(
            ["git", "-C", str(root), "show", f"{SUPERVISOR_COMMIT}:{path}"],
            capture_output=True, text=True, check=False,
        )  # fmt: skip
    if shown.returncode != 0:
        raise SupervisorMissingError(f"{root}: no {path} at {SUPERVISOR_COMMIT[:12]}")
    return shown.stdout


def _root() -> Path:
    named = os.environ.get("SUPERVISOR_SRC")
    for root in [Path(named)] if named else SUPERVISOR_CANDIDATES:
        if root.exists():
            return root
    raise SupervisorMissingError(
        f"no Supervisor source at {SUPERVISOR_VERSION} ({SUPERVISOR_COMMIT[:12]}): clone "
        "github.com/home-assistant/supervisor, check out that commit and set SUPERVISOR_SRC "
        "to the clone (the CI workflow does)"
    )


def _stand_ins() -> dict[str, types.ModuleType]:
    """Modules of the running Supervisor the rules import names from but never call."""

    class CoreSysAttributes:
        coresys: Any

    class HardwareNotFound(Exception):  # noqa: N818 - the Supervisor's name
        pass

    def module(name: str, **names: Any) -> types.ModuleType:
        made = types.ModuleType(name)
        made.__dict__.update(names)
        return made

    class RequestKey:
        def __init__(self, name: str) -> None:
            self.name = name

        def __class_getitem__(cls, item: Any) -> type:
            return cls

    web = module("aiohttp.web", RequestKey=RequestKey)
    return {
        "aiohttp": module("aiohttp", __version__="stand-in", web=web),
        "aiohttp.web": web,
        "supervisor.coresys": module(
            "supervisor.coresys", CoreSys=object, CoreSysAttributes=CoreSysAttributes
        ),
        "supervisor.exceptions": module("supervisor.exceptions", HardwareNotFound=HardwareNotFound),
        "supervisor.hardware.data": module("supervisor.hardware.data", Device=object),
        "supervisor.utils.dt": module("supervisor.utils.dt", get_time_zone=lambda name: name),
    }


@cache
def load() -> dict[str, types.ModuleType]:
    """The Supervisor's modules by dotted name (``apps.validate``...), loaded once."""
    root = _root()
    saved = {
        k: v
        for k, v in sys.modules.items()
        if k == "supervisor" or k.startswith(("supervisor.", "aiohttp"))
    }
    loaded: dict[str, types.ModuleType] = {}
    try:
        for package in PACKAGES:
            name = f"supervisor.{package}" if package else "supervisor"
            made = types.ModuleType(name)
            made.__path__ = []
            sys.modules[name] = made
        for name, stand_in in _stand_ins().items():
            if not (name == "aiohttp" and "aiohttp" in saved):
                sys.modules[name] = stand_in
        for dotted in MODULES:
            path = f"supervisor/{dotted.replace('.', '/')}.py"
            text = _source(root, path)
            if sys.version_info < (3, 14):
                text = _PEP758.sub(r"\1 (\2):", text)
            name = f"supervisor.{dotted}"
            module = types.ModuleType(name)
            module.__file__ = f"{root}/{path}"
            module.__package__ = name.rpartition(".")[0]
            sys.modules[name] = module
            exec(compile(text, module.__file__, "exec"), module.__dict__)
            loaded[dotted] = module
    finally:
        for name in [
            k for k in sys.modules if k == "supervisor" or k.startswith(("supervisor.", "aiohttp"))
        ]:
            del sys.modules[name]
        sys.modules.update(saved)
    return loaded


@contextmanager
def _advisories() -> Iterator[list[str]]:
    """The warnings the Supervisor's code logs meanwhile (deprecations, ignored keys)."""
    found: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            if record.levelno >= logging.WARNING:
                found.append(record.getMessage())

    handler = Collect()
    logger = logging.getLogger("supervisor")
    logger.addHandler(handler)
    try:
        yield found
    finally:
        logger.removeHandler(handler)


def _errors(invalid: Exception) -> list[str]:
    errors = getattr(invalid, "errors", [invalid])
    return [f"{'.'.join(map(str, getattr(e, 'path', [])))}: {getattr(e, 'msg', e)}" for e in errors]


def config_problems(config: dict[str, Any]) -> list[str]:
    """What the Supervisor refuses in an add-on's config.yaml, and what it warns about."""
    validate = load()["apps.validate"]
    vol = sys.modules.get("voluptuous") or __import__("voluptuous")
    with _advisories() as advisories:
        try:
            validate.SCHEMA_APP_CONFIG(dict(config))
        except vol.Invalid as invalid:
            return _errors(invalid) + advisories
    return advisories


def translation_problems(translations: dict[str, Any]) -> list[str]:
    """What the Supervisor refuses in translations/<language>.yaml."""
    validate = load()["apps.validate"]
    import voluptuous as vol  # noqa: PLC0415 - installed with the test extra

    try:
        validate.SCHEMA_APP_TRANSLATIONS(translations)
    except vol.Invalid as invalid:
        return _errors(invalid)
    return []


def option_problems(options: dict[str, Any], schema: dict[str, Any]) -> list[str]:
    """What the Supervisor refuses in options before it starts the add-on (AppOptions),
    and the options it drops with a warning (keys the schema does not have)."""
    app_options = load()["apps.options"]
    import voluptuous as vol  # noqa: PLC0415

    checker = app_options.AppOptions(None, schema, "Modbus MQTT Bridge", "modbus_mqtt_bridge")
    with _advisories() as advisories:
        try:
            checker.validate(options)
        except vol.Invalid as invalid:
            return _errors(invalid) + advisories
    return advisories
