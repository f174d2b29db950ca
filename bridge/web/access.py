"""Who may use the page's API, and which requests may change anything.

- A request from one of ``ingress_proxies`` (Home Assistant's ingress, 172.30.32.2 in an
  add-on) is let in: Home Assistant has logged the user in.
- With a token configured, every other request carries it: ``Authorization: Bearer
  <token>`` (scripts, curl) or the session cookie the page's login form gets from
  ``POST api/login``. The cookie holds a keyed hash of the token, is HttpOnly and
  SameSite=Strict, so another site's page can neither read nor send it.
- Without a token the page listens on loopback only (the config insists) and answers
  only requests whose ``Host`` is a loopback name: a web page on another site that
  points its own name at 127.0.0.1 (DNS rebinding) is refused. A page listening beyond
  loopback without a token (only with ingress proxies) lets nobody else in, whatever
  ``Host`` a client claims.

A request that changes something (``POST``) must also come from the page itself: a JSON
body (``Content-Type: application/json``, which another site cannot send without
CORS, never granted here), an ``Origin`` naming this host if the browser sends one, and
``Sec-Fetch-Site: same-origin`` if the browser sends that header.
"""

from __future__ import annotations

import hashlib
import hmac
import ipaddress
from dataclasses import dataclass
from http import HTTPStatus
from http.cookies import CookieError, SimpleCookie
from urllib.parse import urlsplit

from bridge.config import MIN_TOKEN, WebConfig
from bridge.errors import ConfigError
from bridge.web.http import Request

COOKIE = "bridge_web"
_LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "[::1]", "::1"})


@dataclass(frozen=True, slots=True)
class Refusal:
    status: HTTPStatus
    message: str


@dataclass(frozen=True, slots=True)
class Access:
    token: str | None
    proxies: frozenset[str]
    loopback: bool = True  # the page listens on this machine only

    @classmethod
    def of(cls, web: WebConfig) -> Access:
        """The access rules of the page's settings; ConfigError when a token source is
        configured but holds no usable token now (the page must not open up without one)."""
        token = web.token_value()
        configured = any(v is not None for v in (web.token, web.token_file, web.token_env))
        if configured and (token is None or len(token) < MIN_TOKEN):
            where = "bridge.web.token_file" if web.token_file is not None else "bridge.web.token"
            raise ConfigError(
                "web page", [f"{where}: the token is missing or shorter than {MIN_TOKEN}"]
            )
        proxies = frozenset(str(a) for a in web.ingress_proxies)
        return cls(token if configured else None, proxies, web.loopback)

    def refusal(self, request: Request) -> Refusal | None:
        """Why ``request`` may not use the API, or None when it may."""
        if self.from_proxy(request):
            return None
        if self.token is not None:
            if self.has_token(request):
                return None
            return Refusal(HTTPStatus.UNAUTHORIZED, "this page needs its token")
        if self.proxies or not self.loopback:
            return Refusal(HTTPStatus.FORBIDDEN, "only Home Assistant's ingress opens this page")
        if _host_name(request.headers.get("host", "")) not in _LOOPBACK_NAMES:
            return Refusal(HTTPStatus.FORBIDDEN, "open the page as localhost or 127.0.0.1")
        return None

    def from_proxy(self, request: Request) -> bool:
        return _normal(request.peer) in self.proxies

    def who(self, request: Request) -> str:
        """Who sent a change, for the log: the Home Assistant user behind ingress (its
        ``X-Remote-User-Name``, believed from the ingress proxy only), else the address."""
        user = request.headers.get("x-remote-user-name", "") if self.from_proxy(request) else ""
        shown = "".join(c for c in user[:64] if c.isprintable())
        return f"{shown} via ingress" if shown else request.peer

    def has_token(self, request: Request) -> bool:
        if self.token is None:
            return False
        scheme, _, given = request.headers.get("authorization", "").partition(" ")
        if scheme.lower() == "bearer" and hmac.compare_digest(given.encode(), self.token.encode()):
            return True
        return hmac.compare_digest(_cookie(request, COOKIE).encode(), self.session().encode())

    def login(self, given: str) -> bool:
        return self.token is not None and hmac.compare_digest(given.encode(), self.token.encode())

    def session(self) -> str:
        """The session cookie's value: a keyed hash of the token (not the token itself)."""
        key = (self.token or "").encode()
        return hmac.new(key, b"modbus-mqtt-bridge web session", hashlib.sha256).hexdigest()

    def cookie_header(self, path: str) -> tuple[str, str]:
        return (
            "Set-Cookie",
            f"{COOKIE}={self.session()}; Path={path}; HttpOnly; SameSite=Strict",
        )


def change_refusal(request: Request, *, proxied: bool) -> Refusal | None:
    """Why a request that changes something did not come from the page itself, or None."""
    content_type = request.headers.get("content-type", "").partition(";")[0].strip().lower()
    if content_type != "application/json":
        return Refusal(HTTPStatus.UNSUPPORTED_MEDIA_TYPE, "send JSON (application/json)")
    fetch_site = request.headers.get("sec-fetch-site")
    if fetch_site is not None and fetch_site not in ("same-origin", "none"):
        return Refusal(HTTPStatus.FORBIDDEN, "requests from other sites are refused")
    origin = request.headers.get("origin")
    host = request.headers.get("host", "").lower()
    if origin is not None and not proxied and urlsplit(origin).netloc.lower() != host:
        return Refusal(HTTPStatus.FORBIDDEN, "requests from other sites are refused")
    return None


def _host_name(host: str) -> str:
    """``Host`` without its port: ``127.0.0.1:8099`` -> ``127.0.0.1``, ``[::1]:80`` -> ``[::1]``."""
    host = host.strip().lower()
    if host.startswith("["):
        return host.partition("]")[0] + "]"
    return host.partition(":")[0]


def _normal(peer: str) -> str:
    """An address as ``ipaddress`` writes it (``::ffff:172.30.32.2`` -> ``172.30.32.2``)."""
    try:
        address = ipaddress.ip_address(peer)
    except ValueError:
        return peer
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        return str(address.ipv4_mapped)
    return str(address)


def _cookie(request: Request, name: str) -> str:
    try:
        cookies = SimpleCookie(request.headers.get("cookie", ""))
    except CookieError:
        return ""
    morsel = cookies.get(name)
    return morsel.value if morsel is not None else ""
