"""Headless Chromium driven over the Chrome DevTools Protocol, for the web page's tests.

``browser(folder)`` starts Debian's ``chromium`` with a fresh profile in ``folder`` (no
network beyond what the page asks for, no first-run, no sync, no component updates) and
yields a ``Page``: ``goto``, ``evaluate`` JavaScript, wait ``until`` an expression is
true, press a key, take a screenshot. ``png_with_text`` and ``png_text`` write and read a
text chunk of a PNG (what a screenshot in docs/ shows, in words, to compare). The browser (its whole process group) is ended
when the block ends.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import itertools
import json
import os
import shutil
import signal
import struct
import subprocess
import urllib.request
import zlib
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import websockets

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = (
    "--headless=new",
    "--no-sandbox",  # root in CI containers
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-extensions",
    "--no-first-run",
    "--no-default-browser-check",
    "--remote-debugging-port=0",
    "--remote-allow-origins=*",
)


class Page:
    """One tab, over its DevTools websocket."""

    def __init__(self, socket: Any) -> None:
        self.socket = socket
        self._ids = itertools.count(1)
        self._waiting: dict[int, asyncio.Future[dict[str, Any]]] = {}

    async def receive(self) -> None:
        async for raw in self.socket:
            message = json.loads(raw)
            future = self._waiting.pop(message.get("id", -1), None)
            if future is not None and not future.done():
                future.set_result(message)

    async def send(self, method: str, **params: Any) -> dict[str, Any]:
        number = next(self._ids)
        future: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()
        self._waiting[number] = future
        await self.socket.send(json.dumps({"id": number, "method": method, "params": params}))
        async with asyncio.timeout(20):
            answer = await future
        if "error" in answer:
            raise AssertionError(f"{method}: {answer['error']}")
        result: dict[str, Any] = answer["result"]
        return result

    async def goto(self, url: str) -> None:
        await self.send("Page.navigate", url=url)

    async def evaluate(self, expression: str) -> Any:
        answer = await self.send(
            "Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True
        )
        if "exceptionDetails" in answer:
            raise AssertionError(f"{expression}: {answer['exceptionDetails']}")
        return answer["result"].get("value")

    async def until(self, expression: str, timeout: float = 10.0) -> Any:
        """The value of ``expression`` once it is truthy (polled; bounded). An expression
        that throws (the element it reads is not rendered yet: a page just navigated to)
        counts as not true yet; the last error is said if it never becomes true."""
        value, error = None, ""
        try:
            async with asyncio.timeout(timeout):
                while True:
                    try:
                        value = await self.evaluate(expression)
                    except AssertionError as thrown:
                        value, error = None, str(thrown)
                    if value:
                        break
                    await asyncio.sleep(0.1)
        except TimeoutError:
            text = await self.evaluate("document.querySelector('main')?.innerText")
            raise AssertionError(
                f"never true: {expression}\n{error}\npage shows:\n{text}"
            ) from None
        return value

    async def press(self, key: str, code: int) -> None:
        """A key pressed and released (Enter: ``press("Enter", 13)``)."""
        text = "\r" if key == "Enter" else ""
        for kind in ("keyDown", "keyUp"):
            await self.send(
                "Input.dispatchKeyEvent",
                type=kind,
                key=key,
                code=key,
                windowsVirtualKeyCode=code,
                nativeVirtualKeyCode=code,
                text=text if kind == "keyDown" else "",
            )

    async def screenshot(self, path: Path, width: int, height: int) -> None:
        await self.send(
            "Emulation.setDeviceMetricsOverride",
            width=width,
            height=height,
            deviceScaleFactor=1,
            mobile=False,
        )
        await asyncio.sleep(0.3)  # one layout at the new size
        shot = await self.send("Page.captureScreenshot", format="png")
        path.write_bytes(base64.b64decode(shot["data"]))

    async def screenshot_whole(self, path: Path, width: int) -> None:
        """The whole page at ``width``, as tall as its content."""
        await self.screenshot(path, width, 400)
        height = await self.evaluate("document.documentElement.scrollHeight")
        await self.screenshot(path, width, int(height))


def png_with_text(png: bytes, keyword: str, text: str) -> bytes:
    """``png`` with an iTXt chunk: ``keyword`` -> ``text`` (UTF-8), placed before IEND."""
    data = keyword.encode("latin-1") + b"\0\0\0\0\0" + text.encode("utf-8")
    chunk = _chunk(b"iTXt", data)
    end = png.rindex(b"IEND") - 4  # the IEND chunk's length field
    return png[:end] + chunk + png[end:]


def png_text(png: bytes, keyword: str) -> str | None:
    """The text of ``png``'s iTXt chunk ``keyword`` (uncompressed), or None."""
    at = 8  # after the signature
    while at + 8 <= len(png):
        (length,) = struct.unpack(">I", png[at : at + 4])
        kind, data = png[at + 4 : at + 8], png[at + 8 : at + 8 + length]
        name, _, rest = data.partition(b"\0")
        if kind == b"iTXt" and name == keyword.encode("latin-1") and rest[:1] == b"\0":
            _language, _, rest = rest[2:].partition(b"\0")
            _translated, _, text = rest.partition(b"\0")
            return text.decode("utf-8")
        at += 12 + length
    return None


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


@contextlib.asynccontextmanager
async def browser(folder: Path) -> AsyncIterator[Page]:
    if CHROMIUM is None:
        raise RuntimeError("no chromium on PATH")
    profile = folder / "chromium-profile"
    log = (folder / "chromium.log").open("wb")
    process = subprocess.Popen(
        [CHROMIUM, *FLAGS, f"--user-data-dir={profile}", "about:blank"],
        stdout=log,
        stderr=log,
        start_new_session=True,  # its own process group: renderers end with it
    )
    try:
        port = await _devtools_port(profile, process)
        url = await asyncio.to_thread(_page_socket, port)
        async with websockets.connect(url, max_size=None) as socket:
            page = Page(socket)
            receiving = asyncio.create_task(page.receive())
            try:
                await page.send("Page.enable")
                await page.send("Runtime.enable")
                yield page
            finally:
                receiving.cancel()
                with contextlib.suppress(asyncio.CancelledError, websockets.ConnectionClosed):
                    await receiving
    finally:
        _end(process)
        log.close()


async def _devtools_port(profile: Path, process: subprocess.Popen[bytes]) -> int:
    """The port Chromium wrote to DevToolsActivePort once it listens."""
    active = profile / "DevToolsActivePort"
    async with asyncio.timeout(30):
        while True:
            if process.poll() is not None:
                raise RuntimeError(f"chromium ended at start (exit code {process.returncode})")
            lines = active.read_text().split("\n") if active.exists() else []
            if lines and lines[0].strip().isdigit():
                return int(lines[0])
            await asyncio.sleep(0.1)


def _page_socket(port: int) -> str:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as answer:
        targets = json.load(answer)
    page = next(t for t in targets if t.get("type") == "page")
    url: str = page["webSocketDebuggerUrl"]
    return url


def _end(process: subprocess.Popen[bytes]) -> None:
    """End the browser and its helper processes (its process group), by its id."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(process.pid, signal.SIGTERM)
    try:
        process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait(timeout=10)
