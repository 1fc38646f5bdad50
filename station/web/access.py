"""Who may read the web view, and from where: the `[web]` section of the station config, the Host
check, the login, the security headers (docs/web.md, "Access").

- `[web]` (all optional):

      [web]
      login = "beyond-loopback"          # or "always": ask for a login on 127.0.0.1 too (behind a proxy)
      allowed_hosts = ["fleet.lab.example"]   # names (or name:port) browsers may reach the view by
      [web.users.jdoe]
      password_hash = "$argon2id$v=19$..."    # `station web --hash-password` prints one
      role = "auditor"                        # "viewer": every page; "auditor": also certificate PDFs

- `WebAccess.middleware(app, ...)`: an ASGI wrapper that refuses a Host header that is not the
  address the view listens on (a DNS-rebinding page reaches 127.0.0.1 under its own name, so its
  Host is its own name), asks for HTTP Basic credentials when a login is required, and adds the
  Content-Security-Policy, nosniff and frame-ancestors headers to every response, errors included.

Passwords are stored as argon2id hashes (argon2-cffi): the PHC's winner, memory-hard, and
argon2-cffi is maintained by the Python Software Foundation's Hynek Schlawack and widely used;
plain-text passwords in a config are refused.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import hmac
import html
import ipaddress
import os
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from procedures.vocabulary import InputError

ROLES = {"viewer": "every page", "auditor": "every page and the certificate PDFs"}
LOGIN_MODES = ("beyond-loopback", "always")
REALM = "station fleet"

# Pages are server-drawn HTML + SVG with one stylesheet: nothing inline, no script, no frame;
# 'none' by default so an injected tag could neither run nor fetch.
CSP = ("default-src 'none'; style-src 'self'; img-src 'self' data:; form-action 'self'; base-uri 'none'; "
       "frame-ancestors 'none'")
SECURITY_HEADERS = [
    (b"content-security-policy", CSP.encode()),
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"DENY"),  # frame-ancestors for browsers older than CSP 2
    (b"referrer-policy", b"no-referrer"),
]


@dataclass
class WebUser:
    name: str
    password_hash: str
    role: str


@dataclass
class WebAccess:
    """The `[web]` section: login mode, users, extra host names."""

    login: str = "beyond-loopback"
    allowed_hosts: list[str] = field(default_factory=list)
    users: dict[str, WebUser] = field(default_factory=dict)

    def login_required(self, loopback: bool) -> bool:
        return self.login == "always" or not loopback


def parse_web_section(p: Path | str, table: Any) -> WebAccess:
    """The `[web]` table of the station TOML at `p`; InputError naming file, section and key."""
    if not isinstance(table, dict):
        raise InputError(f"{p}: web must be a section ([web] and its keys), got {table!r}")
    out = WebAccess()
    for key, value in table.items():
        if key == "login":
            if value not in LOGIN_MODES:
                raise InputError(f"{p}: [web] login = {value!r}: give one of {', '.join(LOGIN_MODES)}")
            out.login = value
        elif key == "allowed_hosts":
            if not isinstance(value, list) or not all(isinstance(v, str) and v.strip() for v in value):
                raise InputError(f"{p}: [web] allowed_hosts: a list of host names, e.g. [\"fleet.lab.example\"]")
            out.allowed_hosts = [v.strip().lower().rstrip(".") for v in value]
        elif key == "users":
            if not isinstance(value, dict):
                raise InputError(f"{p}: [web] users: give each user as [web.users.NAME]")
            for name, u in value.items():
                out.users[name] = _user(p, name, u)
        else:
            raise InputError(f"{p}: [web] {key}: unknown key (known: login, allowed_hosts, users)")
    return out


def _user(p, name: str, u: Any) -> WebUser:
    where = f"{p}: [web.users.{name}]"
    if not isinstance(u, dict):
        raise InputError(f"{where}: a section with password_hash and role")
    if ":" in name or not name.isprintable() or not name:
        raise InputError(f"{where}: a user name holds no ':' and no control character (HTTP Basic login)")
    unknown = set(u) - {"password_hash", "role"}
    if unknown:
        raise InputError(f"{where} {sorted(unknown)[0]}: unknown key (known: password_hash, role)")
    h, role = u.get("password_hash"), u.get("role", "viewer")
    if not isinstance(h, str) or not h.startswith("$argon2"):
        raise InputError(f"{where} password_hash: not an argon2 hash; `station web --hash-password` prints one "
                         "(passwords are never stored in clear)")
    from argon2.exceptions import InvalidHashError  # noqa: PLC0415
    from argon2 import extract_parameters  # noqa: PLC0415

    try:
        extract_parameters(h)
    except (InvalidHashError, ValueError):
        raise InputError(f"{where} password_hash: not a valid argon2 hash (cut or edited?); "
                         "`station web --hash-password` prints one") from None
    if role not in ROLES:
        raise InputError(f"{where} role = {role!r}: give one of {', '.join(ROLES)} "
                         f"({'; '.join(f'{k}: {v}' for k, v in ROLES.items())})")
    return WebUser(name, h, role)


def hash_password(password: str) -> str:
    """An argon2id hash (argon2-cffi's defaults, RFC 9106's second recommended option) of `password`."""
    from argon2 import PasswordHasher  # noqa: PLC0415

    return PasswordHasher().hash(password)


# ---------------------------------------------------------------------------- the listening address

def resolve(host: str) -> list[ipaddress.IPv4Address | ipaddress.IPv6Address]:
    """The addresses `host` stands for (an address, or a name resolved here); InputError if none."""
    try:
        return [ipaddress.ip_address(host.strip("[]"))]
    except ValueError:
        pass
    try:
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as exc:
        why = getattr(exc, "strerror", None) or str(exc)
        raise InputError(f"--host {host}: not an address of this machine ({why}); give 127.0.0.1 (this machine "
                         "only) or an address of one of its interfaces") from None
    return sorted({ipaddress.ip_address(i[4][0].split("%")[0]) for i in infos}, key=str)


def is_loopback(host: str) -> bool:
    """Whether every address `host` stands for is a loopback address (reachable from this machine only)."""
    return all(a.is_loopback for a in resolve(host))


def allowed_host_names(host: str, access: WebAccess) -> set[str]:
    """Host header names (without port) a browser reaching the view at `host` may send."""
    names = {n.lower() for n in access.allowed_hosts}
    h = host.strip("[]").lower()
    wildcard = h in ("0.0.0.0", "::", "")
    names.add(h)
    if wildcard or is_loopback(host):
        names |= {"localhost", "127.0.0.1", "::1"}
    if wildcard:  # every name of this machine; addresses are checked as addresses (host_allowed)
        for n in (socket.gethostname(), socket.getfqdn()):
            if n:
                names.add(n.lower().rstrip("."))
    return names


def split_host(value: str) -> tuple[str, int | None] | None:
    """A Host header's (name, port); None when it is not one."""
    v = value.strip().lower()
    if not v:
        return None
    if v.startswith("["):  # [v6]:port
        end = v.find("]")
        if end < 0:
            return None
        name, rest = v[1:end], v[end + 1:]
        if rest and not rest.startswith(":"):
            return None
        port_text = rest[1:] if rest else ""
    else:
        name, _, port_text = v.partition(":")
    if port_text and not (port_text.isascii() and port_text.isdigit() and 0 < int(port_text) < 65536):
        return None
    return name.rstrip("."), (int(port_text) if port_text else None)


def host_allowed(value: str | None, names: set[str], port: int, wildcard: bool,
                 proxy_names: set[str] | None = None) -> bool:
    """Whether a request's Host header `value` names this server: one of `names` (or, listening
    on every interface, an address: a rebinding page is reached by a name, never by an address)
    at the listening `port`; names in `proxy_names` (`[web] allowed_hosts`) on any port, since a
    reverse proxy's port is its own."""
    parsed = split_host(value or "")
    if parsed is None:
        return False
    name, p = parsed
    if name in (proxy_names or set()):
        return True
    if p is not None and p != port:
        return False
    if name in names:
        return True
    if wildcard:
        try:
            ipaddress.ip_address(name)
            return True
        except ValueError:
            return False
    return False


# ---------------------------------------------------------------------------- the ASGI wrapper

class _Verified:
    """Recently verified credentials, by an HMAC of the header (a per-process key): argon2 costs
    ~0.1 s and 64 MiB by design, too much for every stylesheet and page of a session."""

    TTL_S = 600.0
    SIZE = 256

    def __init__(self) -> None:
        self.key = os.urandom(32)
        self.seen: dict[bytes, tuple[float, str, str]] = {}
        self.lock = threading.Lock()

    def digest(self, header: bytes) -> bytes:
        return hmac.new(self.key, header, hashlib.sha256).digest()

    def get(self, header: bytes) -> tuple[str, str] | None:
        d = self.digest(header)
        with self.lock:
            hit = self.seen.get(d)
            if hit and hit[0] > time.monotonic():
                return hit[1], hit[2]
            self.seen.pop(d, None)
        return None

    def put(self, header: bytes, user: str, role: str) -> None:
        with self.lock:
            if len(self.seen) >= self.SIZE:
                self.seen.clear()
            self.seen[self.digest(header)] = (time.monotonic() + self.TTL_S, user, role)


def _page(status: int, title: str, message: str) -> bytes:
    # the same look as the app's error pages (templates/error.html), without the catalog footer
    return (f'<!doctype html><html lang="en"><head><meta charset="utf-8"><title>{status} {title}</title>'
            '<link rel="icon" href="data:,"><link rel="stylesheet" href="/static/style.css"></head><body><main>'
            f'<h1 class="error">{status} {html.escape(title)}</h1><p id="message">{html.escape(message)}</p>'
            '</main></body></html>').encode()


class Guard:
    """ASGI middleware: Host check, then login (when `users` is given), then the app; every
    response gets SECURITY_HEADERS. `host`/`port`: where the view listens."""

    def __init__(self, app, *, host: str, port: int, access: WebAccess, login: bool) -> None:
        self.app = app
        self.port = port
        self.listen = f"{host}:{port}" if ":" not in host else f"[{host}]:{port}"
        self.wildcard = host.strip("[]") in ("0.0.0.0", "::", "")
        self.names = allowed_host_names(host, access)
        self.proxy_names = set(access.allowed_hosts)
        self.users = access.users if login else None
        self.verified = _Verified()

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)

        async def send_with_headers(message):
            if message["type"] == "http.response.start":
                have = {k.lower() for k, _ in message.get("headers", [])}
                message = {**message, "headers": list(message.get("headers", []))
                           + [(k, v) for k, v in SECURITY_HEADERS if k not in have]}
            await send(message)

        headers = dict(scope.get("headers") or [])
        host = headers.get(b"host", b"").decode("latin-1")
        if not host_allowed(host, self.names, self.port, self.wildcard, self.proxy_names):
            return await self._reply(send_with_headers, 400, "Bad request",
                                     f"Host {host!r} is not this server: it listens on {self.listen}; open "
                                     f"http://{self.listen}/ (a name of yours goes in [web] allowed_hosts)")
        if self.users is not None:
            who = await self._login(headers.get(b"authorization"))
            if who is None:
                return await self._reply(send_with_headers, 401, "Login required",
                                         "log in with a user of the station config's [web.users]",
                                         [(b"www-authenticate", f'Basic realm="{REALM}", charset="UTF-8"'.encode())])
            scope = {**scope, "state": {**(scope.get("state") or {}), "web_user": who[0], "web_role": who[1]}}
        return await self.app(scope, receive, send_with_headers)

    async def _login(self, header: bytes | None) -> tuple[str, str] | None:
        if not header or not header[:6].lower() == b"basic ":
            return None
        hit = self.verified.get(header)
        if hit:
            return hit
        try:
            user, sep, password = base64.b64decode(header[6:].strip(), validate=True).decode("utf-8").partition(":")
        except (binascii.Error, UnicodeDecodeError):
            return None
        u = self.users.get(user) if sep else None
        if u is None:
            return None
        from argon2 import PasswordHasher  # noqa: PLC0415
        from argon2.exceptions import Argon2Error, InvalidHashError  # noqa: PLC0415

        from starlette.concurrency import run_in_threadpool  # noqa: PLC0415

        def check() -> bool:
            try:
                return PasswordHasher().verify(u.password_hash, password)
            except (Argon2Error, InvalidHashError):
                return False

        if not await run_in_threadpool(check):  # ~0.1 s of hashing: off the event loop
            return None
        self.verified.put(header, u.name, u.role)
        return u.name, u.role

    @staticmethod
    async def _reply(send, status: int, title: str, message: str, extra: list | None = None) -> None:
        body = _page(status, title, message)
        await send({"type": "http.response.start", "status": status,
                    "headers": [(b"content-type", b"text/html; charset=utf-8"),
                                (b"content-length", str(len(body)).encode()), *(extra or [])]})
        await send({"type": "http.response.body", "body": body})
