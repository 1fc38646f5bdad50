"""Where `station web` listens, checked before anything is printed: the port's range, whether the
address is beyond this machine (then a login is required: station/web/access.py), and the socket
bound here and handed to uvicorn, so a busy port is one line (exit 2) and never uvicorn's
`[Errno 98]` after the URL was already printed.
"""

from __future__ import annotations

import errno
import socket

from procedures.vocabulary import InputError
from station.web.access import WebAccess, is_loopback


def check_port(port: int) -> int:
    """`port` if it is a TCP port 1..65535 (station/values.PORT: the one rule for ports), else
    InputError; checked here too since uvicorn would take the value to bind()."""
    from station.values import PORT  # noqa: PLC0415

    return PORT.parse(port, "--port")


def login_needed(host: str, access: WebAccess, config: str | None) -> bool:
    """Whether pages served on `host` need a login; InputError when `host` reaches beyond this
    machine and the config names no user: every leg's history and certificates would be open to
    the network."""
    loopback = is_loopback(host)
    if not access.login_required(loopback):
        return False
    if not access.users:
        if not loopback:
            raise InputError(f"--host {host}: listening beyond this machine needs a login; add [web.users.NAME] "
                             f"(password_hash, role) to {'--config ' + config if config else 'a --config file'} "
                             "and put TLS in front (docs/web.md, \"Access\"), or listen on 127.0.0.1")
        raise InputError(f"{config}: [web] login = \"always\" but no [web.users.NAME]; add one "
                         "(`station web --hash-password` prints its password_hash)")
    return True


def bind(host: str, port: int) -> socket.socket:
    """A TCP socket bound to host:port (uvicorn listens on it); InputError when it cannot be."""
    try:
        family, kind, proto, _, addr = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM,
                                                          flags=socket.AI_PASSIVE)[0]
    except (socket.gaierror, UnicodeError) as exc:
        raise InputError(f"--host {host}: not an address of this machine ({exc})") from None
    sock = socket.socket(family, kind, proto)
    # as uvicorn binds: a restart may reuse a port whose old connections linger in TIME_WAIT; a
    # port another process listens on is still refused (EADDRINUSE)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(addr)
    except OSError as exc:
        sock.close()
        where = f"{host}:{port}" if ":" not in host else f"[{host}]:{port}"
        if exc.errno == errno.EADDRINUSE:
            raise InputError(f"{where}: the port is in use (another `station web`?); stop it or give "
                             "another --port") from None
        if exc.errno == errno.EACCES:
            raise InputError(f"{where}: permission denied (ports below 1024 need privileges); give --port 8800") from None
        if exc.errno == errno.EADDRNOTAVAIL:
            raise InputError(f"--host {host}: not an address of this machine; give 127.0.0.1") from None
        raise InputError(f"{where}: cannot listen there ({exc.strerror or exc})") from None
    sock.set_inheritable(True)
    return sock
