"""Process lifecycle for long-running commands: logging set-up and clean stops.

Logs go to stderr as plain lines, or as one JSON object per line (``--log-format json``,
for containers and log shippers): ``time``, ``level``, ``logger``, ``message`` and the
structured fields a record carries (``event``, ``device``, ``unit``, ``bus``...), plus
``exception`` with the traceback when there is one.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Coroutine
from concurrent.futures import Future, ThreadPoolExecutor
from datetime import UTC, datetime
from typing import Any, TypeVar

LOG_FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"
LEVELS = ("debug", "info", "warning", "error")
FORMATS = ("text", "json")
T = TypeVar("T")
SAME_STOP = 1.0  # seconds: a signal this soon after the first is the same stop, delivered twice
_STANDARD = frozenset(vars(logging.makeLogRecord({}))) | {"message", "asctime"}


class JsonFormatter(logging.Formatter):
    """One JSON object per record, with the record's extra fields."""

    def format(self, record: logging.LogRecord) -> str:
        document: dict[str, Any] = {
            "time": datetime.fromtimestamp(record.created, UTC).isoformat(timespec="milliseconds"),
            "level": record.levelname.lower(),
            "logger": record.name,
            "message": record.getMessage(),
        }
        document |= {k: v for k, v in vars(record).items() if k not in _STANDARD}
        if record.exc_info:
            document["exception"] = self.formatException(record.exc_info)
        return json.dumps(document, default=str)


def add_logging_arguments(parser: argparse.ArgumentParser, level: str = "info") -> None:
    """``--log-level`` and ``--log-format``; defaults from BRIDGE_LOG_LEVEL/BRIDGE_LOG_FORMAT."""
    parser.add_argument(
        "--log-level",
        default=os.environ.get("BRIDGE_LOG_LEVEL", level),
        choices=LEVELS,
        help="default %(default)s (environment: BRIDGE_LOG_LEVEL)",
    )
    parser.add_argument(
        "--log-format",
        default=os.environ.get("BRIDGE_LOG_FORMAT", "text"),
        choices=FORMATS,
        help="plain lines or one JSON object per line (environment: BRIDGE_LOG_FORMAT)",
    )


def configure_logging(level: str, log_format: str = "text") -> None:
    """Lines on stderr at ``level`` (pymodbus' own chatter stays quiet)."""
    handler = logging.StreamHandler()
    handler.setFormatter(JsonFormatter() if log_format == "json" else logging.Formatter(LOG_FORMAT))
    logging.basicConfig(level=level.upper(), handlers=[handler], force=True)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


class _DaemonThreads(ThreadPoolExecutor):
    """The event loop's default executor, one daemon thread per job: a stop never waits for
    a job that blocks (paho's connect to a broker that drops the SYN waits 5 s), while a
    pool's threads are joined at exit and ``asyncio.run`` waits for them."""

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future[T]:
        future: Future[T] = Future()

        def run() -> None:
            if future.set_running_or_notify_cancel():
                try:
                    future.set_result(fn(*args, **kwargs))
                except BaseException as exc:  # handed to whoever awaits the job
                    future.set_exception(exc)

        threading.Thread(target=run, name="blocking job", daemon=True).start()
        return future

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Nothing to wait for: daemon threads end with the process."""


async def until_stopped(
    work: Coroutine[Any, Any, None], hangup: Callable[[], None] | None = None
) -> None:
    """Run ``work`` until it ends or SIGINT/SIGTERM arrives (Ctrl-C, ``docker stop``).
    With ``hangup``, SIGHUP calls it (a service's "reload") instead of ending the process,
    which is what SIGHUP's default does.

    The first signal cancels ``work``, which ends within seconds (a write in flight is
    finished, the farewell is bounded); a second one, ``SAME_STOP`` seconds or more later
    (sooner it is the first delivered twice: a terminal's Ctrl-C reaches a wrapper that
    forwards it too), ends the process at once, logged."""
    task = asyncio.ensure_future(work)
    loop = asyncio.get_running_loop()
    loop.set_default_executor(_DaemonThreads())
    first: list[float] = []  # when the first signal came

    def stop(signum: int) -> None:
        now = time.monotonic()
        if not first:
            first.append(now)
            task.cancel()
            return
        if now - first[0] < SAME_STOP:  # one Ctrl-C delivered twice (a wrapper forwards it)
            return
        logging.getLogger(__name__).error(
            "a second stop signal: exiting now, without finishing the stop"
        )
        logging.shutdown()
        os._exit(128 + signum)

    for signum in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(signum, stop, signum)
    if hangup is not None:
        loop.add_signal_handler(signal.SIGHUP, hangup)
    try:
        with contextlib.suppress(asyncio.CancelledError):
            await task
    finally:
        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            loop.remove_signal_handler(signum)
