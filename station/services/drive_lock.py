"""Two stations, one drive: a lock per drive and leg, so that a second station process cannot
push, roll back, verify or sweep on a leg another one is using (docs/reliability.md).

The lock is station-side: one file per (drive, leg) in a lock folder shared by every station
process on this computer, locked with `fcntl.flock` for as long as the drive connection is open.
It holds its owner's description (PID, host, since when, which command), which the refusal
quotes:

    leg 3 of tcp://10.0.0.5:502 is in use by station PID 1234 on HOST since 2026-11-24T18:50:01Z,
    running `station sweep`.

The operating system releases a flock when its process ends, however it ends (SIGKILL, a
crash, a power cut of the PC): no stale lock to clean up. The files stay (empty once released);
they are never removed, because removing a lock file another process is about to lock would
let two processes hold "the" lock at once.

Which drive: `tcp://HOST:PORT` (port 502 by default, host lower-case) or `rtu://DEVICE` (the
device's real path), the unit id being the leg; on the simulated rig, its table memory file
(`[sim] nv_path`, default <recordings_dir>/sim-drive-nv.json, which is the simulated drive's
EEPROM: two station processes using it share that drive). A simulated rig without a memory file
is private to its process and is not locked.

Limits, said plainly: the lock only sees station processes on this computer using the same lock
folder. Two PCs on one bus (or one drive reached through two gateways), another program (mbpoll,
a vendor tool), or one drive named by two host names ("localhost" and "127.0.0.1") are not
covered: that needs a guard in the drive itself (a master-token register), which the drives of
this station do not have.

The lock folder: $STATION_LOCK_DIR, else /tmp/station-locks (created world-writable with the
sticky bit, like /tmp, so that station processes of every user on the PC see one another; a
per-user folder such as $XDG_RUNTIME_DIR would not).
"""

from __future__ import annotations

import fcntl
import functools
import hashlib
import inspect
import json
import os
import re
import socket
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable
from urllib.parse import urlsplit

from drivers.errors import DriverError

LOCK_DIR_ENV = "STATION_LOCK_DIR"
DEFAULT_LOCK_DIR = Path("/tmp/station-locks")


class DriveInUse(DriverError):
    """Another station process is using this leg of this drive (the message says which)."""

    hint = "Nothing was sent to the drive: wait until it has finished, or stop it there, then try again."


def lock_dir() -> Path:
    """The lock folder ($STATION_LOCK_DIR, else /tmp/station-locks), created if missing."""
    folder = Path(os.environ.get(LOCK_DIR_ENV) or DEFAULT_LOCK_DIR)
    if not folder.is_dir():
        try:
            folder.mkdir(parents=True)
            folder.chmod(0o1777)  # every user's station processes lock here; only owners delete
        except FileExistsError:
            pass  # another process made it meanwhile
    return folder


def drive_identity(cfg, whole_rig: bool) -> str | None:
    """The drive a config reaches, as lock files name it; None for a simulated drive private to
    this process. `whole_rig`: opening the whole rig (`open_rig`, simulated when either device
    is) rather than the drives alone (`open_drive`, simulated when the drive is)."""
    sim = cfg.is_sim if whole_rig else cfg.drive.url == "sim"
    if sim:
        nv = cfg.sim.nv_path
        return f"sim:{Path(nv).resolve()}" if nv else None
    url = cfg.drive.url.strip()
    try:
        parts = urlsplit(url)
        if parts.scheme == "tcp" and parts.hostname:
            return f"tcp://{parts.hostname.lower()}:{parts.port or 502}"
        if parts.scheme == "rtu":
            path = (parts.netloc + parts.path) if parts.netloc else parts.path
            return f"rtu://{os.path.realpath(path)}"
    except ValueError:
        pass
    return url  # the client refuses a malformed URL with its own message


def _file_for(drive: str, leg: int) -> Path:
    slug = re.sub(r"[^A-Za-z0-9]+", "_", drive).strip("_")[-60:]
    digest = hashlib.sha1(drive.encode()).hexdigest()[:12]  # slugs of two drives may coincide
    return lock_dir() / f"{slug}-{digest}-leg{leg}.lock"


def command_text() -> str:
    """What this process is running, as a refusal quotes it: `station sweep`, `station ui`..."""
    prog = Path(sys.argv[0]).name if sys.argv and sys.argv[0] else "python"
    if prog in ("station", "__main__.py", "cli.py"):
        sub = next((a for a in sys.argv[1:] if not a.startswith("-")), "ui")
        return f"station {sub}"
    return prog


# A process may hold one lock several times (the terminal UI reconnecting while the old rig
# closes; a test opening the rig twice): flock would refuse the second open file of the same
# process, so the process counts its own holds and keeps one open file per lock.
_held: dict[Path, list] = {}  # path -> [fd, count]
_guard = threading.Lock()


def _owner_text(path: Path, drive: str, leg: int) -> str:
    try:
        owner = json.loads(path.read_text() or "{}")
    except (OSError, ValueError):
        owner = {}
    if not isinstance(owner, dict) or "pid" not in owner:  # the holder is between lock and write
        return f"leg {leg} of {drive} is in use by another station process"
    return (f"leg {leg} of {drive} is in use by station PID {owner.get('pid')} on {owner.get('host', '?')} "
            f"since {owner.get('since_utc', '?')}, running `{owner.get('command', '?')}`")


def _take(path: Path, drive: str, leg: int, command: str) -> None:
    with _guard:
        if path in _held:
            _held[path][1] += 1
            return
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise DriveInUse(_owner_text(path, drive, leg) + ".") from None
        except BaseException:
            os.close(fd)
            raise
        owner = {"pid": os.getpid(), "host": socket.gethostname(), "command": command, "drive": drive, "leg": leg,
                 "since_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(owner).encode(), 0)
        _held[path] = [fd, 1]


def _give(path: Path) -> None:
    with _guard:
        entry = _held.get(path)
        if entry is None:
            return
        entry[1] -= 1
        if entry[1] > 0:
            return
        del _held[path]
        try:
            os.ftruncate(entry[0], 0)  # nobody's: a reader of the file sees no owner
        finally:
            os.close(entry[0])  # releases the flock


@dataclass
class DriveLock:
    """The legs of one drive this process holds; `release()` gives them back (once)."""

    drive: str | None
    paths: list[Path]

    def release(self) -> None:
        paths, self.paths = self.paths, []
        for path in reversed(paths):
            _give(path)

    def __enter__(self) -> "DriveLock":
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def acquire(drive: str | None, legs: Iterable[int], command: str | None = None) -> DriveLock:
    """Lock `legs` of `drive` for this process, all or none (in leg order, so two processes
    asking for overlapping legs cannot deadlock: neither waits). DriveInUse naming the owner
    when another process holds one of them. `drive` None: nothing to lock."""
    if drive is None:
        return DriveLock(None, [])
    command = command or command_text()
    taken = DriveLock(drive, [])
    try:
        for leg in sorted({int(v) for v in legs}):
            path = _file_for(drive, leg)
            _take(path, drive, leg, command)
            taken.paths.append(path)
    except BaseException:
        taken.release()
        raise
    return taken


def lock_for(cfg, legs: int | Iterable[int], whole_rig: bool) -> DriveLock:
    """Lock the legs a config's drive is about to be used on (see `drive_identity`)."""
    legs = (legs,) if isinstance(legs, int) else tuple(legs)
    return acquire(drive_identity(cfg, whole_rig), legs)


def holds_drive_lock(whole_rig: bool) -> Callable:
    """Decorator for the wiring's `open_rig(cfg, legs, ...)` / `open_drive(cfg, legs)`: lock the
    legs before connecting (a refusal sends nothing to the drive), release them when the Rig or
    DriveHandle is closed, or at once if connecting fails."""

    def wrap(opener: Callable) -> Callable:
        sig = inspect.signature(opener)

        @functools.wraps(opener)
        def opened(*args, **kwargs) -> Any:
            bound = sig.bind(*args, **kwargs)
            bound.apply_defaults()
            lock = lock_for(bound.arguments["cfg"], bound.arguments["legs"], whole_rig)
            try:
                handle = opener(*args, **kwargs)
            except BaseException:
                lock.release()
                raise
            if hasattr(handle, "_closers"):  # a Rig: released after everything else closed
                handle._closers.insert(0, lock.release)
            else:  # a DriveHandle
                close = handle.close

                def close_then_release() -> None:
                    try:
                        close()
                    finally:
                        lock.release()

                handle.close = close_then_release
            return handle

        return opened

    return wrap
