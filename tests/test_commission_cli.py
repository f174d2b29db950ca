"""``modbus-mqtt-bridge scan | read | write`` against the real simulator on loopback TCP.

The simulator runs in a background thread with its own event loop, so the commands run
in-process exactly as the console script runs them (``bridge.cli.main``); the Ctrl-C test
runs the console script in a subprocess.
"""

from __future__ import annotations

import asyncio
import json
import os
import pty
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from bridge.cli import main
from bridge.core.entity import Table
from bridge.core.interpret import interpret
from bridge.core.request import Write
from bridge.modbus.simulator import Simulator
from tests.integration.harness import serving_tcp, simulator

ROOT = Path(__file__).resolve().parent.parent


class Served:
    """A simulator serving TCP from a background thread until the block ends."""

    def __init__(self, sim: Simulator) -> None:
        self.sim = sim
        self.port = 0
        self._ready = threading.Event()
        self._thread = threading.Thread(target=asyncio.run, args=(self._serve(),), daemon=True)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None

    async def _serve(self) -> None:
        self._loop, self._stop = asyncio.get_running_loop(), asyncio.Event()
        async with serving_tcp(self.sim) as port:
            self.port = port
            self._ready.set()
            await self._stop.wait()

    def __enter__(self) -> Served:
        self._thread.start()
        if not self._ready.wait(10):
            raise AssertionError("the simulator did not start")
        return self

    def __exit__(self, *_: object) -> None:
        assert self._loop is not None and self._stop is not None
        self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(10)
        assert not self._thread.is_alive()

    @property
    def bus(self) -> str:
        return f"tcp://127.0.0.1:{self.port}"

    def held(self, unit: int, table: Table, first: int, count: int) -> list[int]:
        image = self.sim.image(unit)
        return [image.get((table, address), 0) for address in range(first, first + count)]


@pytest.fixture
def served() -> Iterator[Served]:
    sim = simulator((1, "nastec_vasco"), (3, "p2_vfd"), (4, "smartgen_hgm6100"))
    with Served(sim) as serving:
        yield serving


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


# --- scan -------------------------------------------------------------------------------


def test_scan_json_finds_exactly_the_units(
    served: Served, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run(capsys, "scan", "--bus", served.bus, "--units", "1-6", "--json")
    assert code == 0, err
    document = json.loads(out)
    assert [f["unit"] for f in document["found"]] == [1, 3, 4]
    assert document["scanned"] == [1, 2, 3, 4, 5, 6]
    assert document["complete"] is True
    first = document["found"][0]
    assert (first["answer"], first["exception"], first["detail"]) == (
        "exception",
        2,
        "illegal data address",
    )
    assert "unit 3: exception 2 (illegal data address)" in err  # live, the JSON comes last


def test_scan_prints_a_table(served: Served, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(
        capsys, "scan", "--bus", served.bus, "--units", "4,3,5-6", "--timeout", "0.2"
    )
    assert code == 0
    rows = [line.split() for line in out.splitlines() if line.strip()]
    assert rows[0] == ["UNIT", "ANSWER", "LATENCY"]
    assert [row[0] for row in rows[2:]] == ["4", "3"]
    assert rows[2][1] == "values"  # the genset answers holding 0
    assert rows[3][1:5] == ["exception", "2", "(illegal", "data"]


def test_scan_in_a_terminal_shows_each_unit_once(served: Served) -> None:
    """stdout and stderr on one terminal: the bar counts, the table tells, once."""
    main_fd, side = pty.openpty()
    command = [sys.executable, "-m", "bridge.cli", "scan", "--bus", served.bus]
    env = os.environ | {"COLUMNS": "100", "TERM": "xterm"}
    with subprocess.Popen(
        [*command, "--units", "1-4", "--timeout", "0.2"],
        stdout=side,
        stderr=side,
        env=env,
        cwd=ROOT,
    ) as process:
        os.close(side)
        screen = b""
        try:
            while True:
                try:
                    chunk = os.read(main_fd, 65536)
                except OSError:  # the process closed the terminal
                    break
                if not chunk:
                    break
                screen += chunk
            assert process.wait(20) == 0
        finally:
            if process.poll() is None:
                process.kill()
            os.close(main_fd)
    text = screen.decode(errors="replace")
    assert "3 found" in text  # the bar's count
    # units 1 and 3 answer holding 0 with exception 2: two rows of the table, nothing more
    assert text.count("illegal data address") == 2
    assert "unit 1:" not in text


def test_scan_that_finds_nobody_exits_1(served: Served, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(capsys, "scan", "--bus", served.bus, "--units", "7-8", "--timeout", "0.1")
    assert code == 1
    assert out == ""
    assert f"no unit answered on tcp://127.0.0.1:{served.port}" in err


def test_ctrl_c_stops_a_scan_with_what_it_found(served: Served) -> None:
    command = [sys.executable, "-m", "bridge.cli", "scan", "--bus", served.bus, "--json"]
    command += ["--units", "1-60", "--timeout", "0.5"]
    with subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT
    ) as process:
        try:
            assert process.stderr is not None
            for line in process.stderr:
                if line.startswith("unit 4:"):
                    break
            process.send_signal(signal.SIGINT)
            out, err = process.communicate(timeout=20)
        finally:
            if process.poll() is None:
                process.kill()
    assert process.returncode == 0, err
    document = json.loads(out)
    assert [f["unit"] for f in document["found"]] == [1, 3, 4]
    assert document["complete"] is False
    assert document["scanned"][:4] == [1, 2, 3, 4]
    assert len(document["scanned"]) < 60
    assert f"stopped after {len(document['scanned'])} of 60 units" in err


# --- read -------------------------------------------------------------------------------


def test_read_json_is_the_interpretation_of_what_the_unit_holds(
    served: Served, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run(
        capsys, "read", "--bus", served.bus, "--unit", "3", "0x1000", "4", "--json"
    )
    assert code == 0, err
    held = served.held(3, Table.HOLDING, 0x1000, 4)
    assert json.loads(out) == {
        "unit": 3,
        "table": "holding",
        **interpret(0x1000, held),
        "requests": 1,
        "note": None,
    }


def test_a_pair_on_a_one_register_device_is_read_one_at_a_time(
    served: Served, capsys: pytest.CaptureFixture[str]
) -> None:
    """The troubleshooting recipe ``read ... ADDRESS 2`` on the Nastec, which reads one
    register per request: refused whole, then read register by register, and said so."""
    code, out, err = run(capsys, "read", "--bus", served.bus, "--unit", "1", "151", "2")
    assert code == 0, err
    assert err == "unit 1: read one at a time: the unit refused 2 registers at once\n"
    first, second = served.held(1, Table.HOLDING, 151, 2)
    assert f"151 (0x0097)   0x{first:04X}" in out
    assert f"152 (0x0098)   0x{second:04X}" in out
    assert "ABCD" in out  # the pair, every order


def test_a_register_refused_alone_is_named(
    served: Served, capsys: pytest.CaptureFixture[str]
) -> None:
    """Wire 0x6C is the Nastec's last setting, 0x6D an undocumented index it refuses."""
    code, out, err = run(capsys, "read", "--bus", served.bus, "--unit", "1", "0x6C", "2")
    assert (code, out) == (1, "")
    assert err == ("error: unit 1 refused: exception 2 (illegal data address, at holding 109)\n")


def test_a_configured_device_is_read_within_its_limit(
    served: Served, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """With -c, the device at that unit gives its read limit: split up front."""
    config = tmp_path / "config.yaml"
    config.write_text(
        f"buses: [{{id: line, transport: tcp, host: 127.0.0.1, tcp_port: {served.port}}}]\n"
        "devices: [{id: pump, bus: line, unit: 1, mapping: nastec_vasco}]\n"
    )
    code, out, err = run(
        capsys, "read", "-c", str(config), "--bus", "line", "--unit", "1", "151", "3", "--json"
    )
    assert code == 0, err
    document = json.loads(out)
    assert document["registers"] == served.held(1, Table.HOLDING, 151, 3)
    assert document["requests"] == 3
    assert document["note"] == "3 requests: the device reads at most 1 register at once"


def test_read_shows_every_reading(served: Served, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "read", "--bus", served.bus, "--unit", "3", "4096", "2")
    assert code == 0
    first, second = served.held(3, Table.HOLDING, 0x1000, 2)
    reading = interpret(0x1000, [first, second])
    assert "unit 3 holding registers" in out
    assert f"4096 (0x1000)   0x{first:04X}   {first}" in out
    assert f"4097 (0x1001)   0x{second:04X}   {second}" in out
    for order in ("ABCD", "CDAB", "BADC", "DCBA"):
        values = reading["pairs"][0][order]
        assert f"{order}    {values['u32']}" in " ".join(out.split(" ")), order


def test_read_coils(served: Served, capsys: pytest.CaptureFixture[str]) -> None:
    args = ("read", "--bus", served.bus, "--unit", "4", "--table", "coil", "64", "10")
    code, out, err = run(capsys, *args, "--json")
    assert code == 0, err
    document = json.loads(out)
    assert document["bits"] == served.held(4, Table.COIL, 64, 10)
    code, out, _ = run(capsys, *args)
    assert code == 0
    lines = [line.split() for line in out.splitlines() if "(0x00" in line]
    assert [line[2] == "ON" for line in lines] == [bit == 1 for bit in document["bits"]]


def test_read_of_an_absent_unit_exits_1(served: Served, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(
        capsys, "read", "--bus", served.bus, "--unit", "2", "54", "--timeout", "0.2"
    )
    assert (code, out) == (1, "")
    assert err == "error: unit 2 did not answer within 0.2 s\n"


def test_read_beyond_the_limit_exits_2(served: Served, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "read", "--bus", served.bus, "--unit", "1", "0", "126")
    assert code == 2
    assert "count 126: read 1..125 registers at a time (nothing sent)" in err


# --- write ------------------------------------------------------------------------------


def test_write_then_read_back(served: Served, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(capsys, "write", "--bus", served.bus, "--unit", "1", "0x36", "0x7B")
    assert code == 0, err
    assert out == "unit 1: wrote 0x007B (123) to holding 54 (0x0036) with FC06\n"
    assert served.sim.writes == [(1, Write(6, Table.HOLDING, 54, (123,)))]
    code, out, _ = run(capsys, "read", "--bus", served.bus, "--unit", "1", "54", "--json")
    assert json.loads(out)["registers"] == [123]


def test_write_json_and_fc05(served: Served, capsys: pytest.CaptureFixture[str]) -> None:
    args = ("write", "--bus", served.bus, "--unit", "4", "--table", "coil", "--coil-on", "0x00FF")
    code, out, err = run(capsys, *args, "2", "1", "--json")
    assert code == 0, err
    assert json.loads(out) == {
        "unit": 4,
        "function": 5,
        "table": "coil",
        "address": 2,
        "values": [0x00FF],
    }
    assert served.sim.writes == [(4, Write(5, Table.COIL, 2, (0x00FF,)))]


@pytest.mark.parametrize(
    ("values", "message"),
    [
        (["70000"], "register value 70000: write 0..65535 (0x0000..0xFFFF; -1 is 0xFFFF)"),
        (["-1"], "register value -1: write 0..65535 (0x0000..0xFFFF; -1 is 0xFFFF)"),
        (["1"] * 124, "124 values: FC16 writes 1..123 registers"),
    ],
)
def test_a_bad_value_exits_2_and_sends_nothing(
    served: Served, capsys: pytest.CaptureFixture[str], values: list[str], message: str
) -> None:
    code, out, err = run(capsys, "write", "--bus", served.bus, "--unit", "1", "54", *values)
    assert (code, out) == (2, "")
    assert err == f"error: {message} (nothing sent)\n"
    assert served.sim.writes == []


def test_a_refused_write_exits_1_naming_the_exception(
    served: Served, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ("write", "--bus", served.bus, "--unit", "1", "--function", "16", "54", "5")
    code, out, err = run(capsys, *args)
    assert (code, out) == (1, "")
    assert err == "error: unit 1 refused: exception 1 (illegal function)\n"
    code, _, err = run(capsys, "write", "--bus", served.bus, "--unit", "3", "0", "5")
    assert (code, err) == (1, "error: unit 3 refused: exception 2 (illegal data address)\n")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--unit", "1", "0xZZ", "1"], "argument ADDRESS: '0xZZ' is not a decimal or 0x hex"),
        (["--unit", "0", "54", "1"], "argument --unit: unit 0: use 1..255 (0 is broadcast)"),
        (["--unit", "1", "--table", "input", "54", "1"], "argument --table: invalid choice"),
    ],
)
def test_unparsable_arguments_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    with pytest.raises(SystemExit) as caught:
        main(["write", "--bus", "tcp://127.0.0.1", *args])
    assert caught.value.code == 2
    assert message in capsys.readouterr().err


# --- buses ------------------------------------------------------------------------------


def test_a_bus_from_the_config_file(
    served: Served, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    config = tmp_path / "config.yaml"
    config.write_text(
        f"buses:\n  - id: plant\n    transport: tcp\n    host: 127.0.0.1\n    tcp_port: {served.port}\n"
    )
    code, out, err = run(capsys, "read", "-c", str(config), "--bus", "plant", "--unit", "1", "54")
    assert code == 0, err
    assert "54 (0x0036)" in out
    code, _, err = run(capsys, "read", "-c", str(config), "--bus", "line", "--unit", "1", "54")
    assert code == 2
    assert "buses: no bus 'line' (have ['plant'])" in err


@pytest.mark.parametrize(
    ("bus", "message"),
    [
        ("udp://10.0.0.1", "bus 'udp://10.0.0.1': 1 error(s)\n  use one of: tcp://HOST[:PORT]"),
        ("rs485", "a bus id needs -c CONFIG; or give a spec: tcp://HOST[:PORT]"),
        ("rtu:///dev/ttyUSB0?parity=X", "parity: Input should be 'N', 'E' or 'O'"),
    ],
)
def test_a_bad_bus_exits_2(capsys: pytest.CaptureFixture[str], bus: str, message: str) -> None:
    code, _, err = run(capsys, "read", "--bus", bus, "--unit", "1", "54")
    assert code == 2
    assert message in err


def test_a_bus_that_cannot_be_reached_exits_1(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "scan", "--bus", "rtu:///dev/nonexistent-tty", "--units", "1")
    assert code == 1
    assert err.startswith("error: bus: cannot open /dev/nonexistent-tty")
    assert "scanning" not in err  # no progress bar before the bus is open


def test_help_says_addresses_are_wire_addresses(capsys: pytest.CaptureFixture[str]) -> None:
    for command in ("read", "write"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        help_text = " ".join(capsys.readouterr().out.split())
        assert "wire address (0-based, as sent in the frame), decimal or 0x hex" in help_text
