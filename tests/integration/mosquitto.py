"""A private mosquitto broker on a free loopback port (never the system broker on 1883).

``Broker.start()`` writes a config into its own folder and waits (bounded) until the port
accepts connections; ``restart()`` stops and starts it on the same port. Variants: a
password file (``users``) and TLS (``tls``, certificates made by ``make_tls_files`` with
the openssl CLI, optionally requiring a client certificate), an ACL file (``acl``: it
filters what clients publish and receive but never refuses a SUBSCRIBE) and the dynamic
security plugin (``subscribe_acl``: anonymous clients may subscribe only as it allows,
others get SUBACK 0x87, 0x80 on 3.1.1).
"""

from __future__ import annotations

import getpass
import json
import os
import shutil
import socket
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

from tests.ports import free_port

MOSQUITTO = "/usr/sbin/mosquitto"
DYNSEC = "/usr/lib/x86_64-linux-gnu/mosquitto_dynamic_security.so"
HOST = "127.0.0.1"


@dataclass(frozen=True)
class TlsFiles:
    """A CA, a server and a client certificate signed by it, and an unrelated CA."""

    ca: Path
    server_cert: Path
    server_key: Path
    client_cert: Path
    client_key: Path
    other_ca: Path


@dataclass
class Broker:
    workdir: Path
    users: dict[str, str] = field(default_factory=dict)
    tls: TlsFiles | None = None
    require_certificate: bool = False
    acl: list[str] = field(default_factory=list)  # acl_file lines (anonymous clients)
    # dynamic security ACLs of anonymous clients ({"acltype": "subscribeLiteral", "topic":
    # ..., "allow": True}); when given, any other subscription is refused
    subscribe_acl: list[dict[str, object]] | None = None
    host: str = HOST
    port: int = 0
    process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"{'mqtts' if self.tls else 'mqtt'}://{self.host}:{self.port}"

    @property
    def log(self) -> str:
        path = self.workdir / "mosquitto.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def start(self) -> None:
        """Start on ``port``, or on a free port (retried if another process takes it)."""
        if self.port:
            self._launch()
            return
        for attempt in range(3):
            self.port = free_port()
            try:
                self._launch()
                return
            except RuntimeError:
                if attempt == 2:
                    raise

    def stop(self) -> None:
        if self.process is None:
            return
        self.process.terminate()
        try:
            self.process.wait(5)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(5)
        self.process = None

    def restart(self) -> None:
        self.stop()
        self._launch()

    def _launch(self) -> None:
        config = self.workdir / "mosquitto.conf"
        config.write_text(self._config())
        with (self.workdir / "mosquitto.log").open("ab") as log:
            self.process = subprocess.Popen(
                [MOSQUITTO, "-c", str(config)], stdout=log, stderr=subprocess.STDOUT
            )
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                self.process = None
                raise RuntimeError(f"mosquitto exited on port {self.port}:\n{self.log}")
            try:
                with socket.create_connection((self.host, self.port), timeout=0.2):
                    return
            except OSError:
                time.sleep(0.02)
        self.stop()
        raise RuntimeError(f"mosquitto did not listen on port {self.port} within 5 s:\n{self.log}")

    def _config(self) -> str:
        lines = [
            f"listener {self.port} {self.host}",
            f"allow_anonymous {'false' if self.users else 'true'}",
            "persistence false",
            "log_dest stderr",
            "log_type error warning notice information",
            f"user {getpass.getuser()}",  # as root: do not drop to 'mosquitto' (tmp files)
        ]
        if self.users:
            lines.append(f"password_file {self._password_file()}")
        if self.acl:
            acl = self.workdir / "acl"
            acl.write_text("\n".join(self.acl) + "\n")
            lines.append(f"acl_file {acl}")
        if self.subscribe_acl is not None:
            lines += [f"plugin {DYNSEC}", f"plugin_opt_config_file {self._dynsec_file()}"]
        if self.tls:
            lines += [
                f"cafile {self.tls.ca}",
                f"certfile {self.tls.server_cert}",
                f"keyfile {self.tls.server_key}",
                f"require_certificate {'true' if self.require_certificate else 'false'}",
            ]
        return "\n".join(lines) + "\n"

    def _dynsec_file(self) -> Path:
        path = self.workdir / "dynamic-security.json"
        access = {"publishClientSend": True, "publishClientReceive": True, "unsubscribe": True}
        document = {
            "defaultACLAccess": access | {"subscribe": False},
            "clients": [],
            "groups": [{"groupname": "anonymous", "roles": [{"rolename": "anonymous"}]}],
            "roles": [{"rolename": "anonymous", "acls": self.subscribe_acl}],
            "anonymousGroup": "anonymous",
        }
        path.write_text(json.dumps(document))
        return path

    def _password_file(self) -> Path:
        path = self.workdir / "passwd"
        if not path.exists():
            tool = shutil.which("mosquitto_passwd")
            assert tool is not None, "check has_mosquitto_passwd() first"
            for create, (user, password) in enumerate(self.users.items()):
                flags = ["-b", "-c"] if create == 0 else ["-b"]
                subprocess.run([tool, *flags, str(path), user, password], check=True, timeout=10)
            path.chmod(0o600)
        return path


def has_mosquitto() -> bool:
    return os.access(MOSQUITTO, os.X_OK)


def has_dynamic_security() -> bool:
    return has_mosquitto() and os.path.exists(DYNSEC)


def has_mosquitto_passwd() -> bool:
    return shutil.which("mosquitto_passwd") is not None


def make_tls_files(folder: Path) -> TlsFiles:
    """A throwaway PKI made with the openssl CLI (EC P-256 keys, valid for two days)."""
    folder.mkdir(parents=True, exist_ok=True)
    ca, other_ca = folder / "ca", folder / "other-ca"
    _self_signed(ca, "bridge test CA")
    _self_signed(other_ca, "untrusted test CA")
    server = _signed(ca, folder / "server", "localhost", "serverAuth", "IP:127.0.0.1,DNS:localhost")
    client = _signed(ca, folder / "client", "bridge", "clientAuth", "DNS:bridge")
    return TlsFiles(
        ca=ca.with_suffix(".crt"),
        server_cert=server.with_suffix(".crt"),
        server_key=server.with_suffix(".key"),
        client_cert=client.with_suffix(".crt"),
        client_key=client.with_suffix(".key"),
        other_ca=other_ca.with_suffix(".crt"),
    )


_KEY = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes"]


def _openssl(*args: str) -> None:
    subprocess.run(["openssl", *args], check=True, capture_output=True, timeout=30)


def _self_signed(stem: Path, name: str) -> None:
    _openssl(
        "req", "-x509", *_KEY, "-days", "2", "-subj", f"/CN={name}",
        "-keyout", str(stem.with_suffix(".key")), "-out", str(stem.with_suffix(".crt")),
        "-addext", "basicConstraints=critical,CA:TRUE",
        "-addext", "keyUsage=critical,keyCertSign,cRLSign",
    )  # fmt: skip


def _signed(ca: Path, stem: Path, name: str, usage: str, alt_names: str) -> Path:
    csr, extensions = stem.with_suffix(".csr"), stem.with_suffix(".ext")
    extensions.write_text(
        f"basicConstraints=CA:FALSE\nkeyUsage=critical,digitalSignature\n"
        f"extendedKeyUsage={usage}\nsubjectAltName={alt_names}\n"
        "subjectKeyIdentifier=hash\nauthorityKeyIdentifier=keyid,issuer\n"
    )
    _openssl("req", *_KEY, "-subj", f"/CN={name}", "-keyout", str(stem.with_suffix(".key")),
             "-out", str(csr))  # fmt: skip
    _openssl(
        "x509", "-req", "-in", str(csr), "-days", "2", "-set_serial", str(time.time_ns()),
        "-CA", str(ca.with_suffix(".crt")), "-CAkey", str(ca.with_suffix(".key")),
        "-extfile", str(extensions), "-out", str(stem.with_suffix(".crt")),
    )  # fmt: skip
    return stem
