"""A faulty link between the station and the simulated rig, for fault-injection tests and the soak.

Two tools, both seeded and both counting what they injected (`counts`, per kind):

- `ModbusFaultProxy`: a Modbus TCP proxy on 127.0.0.1 between a client and a drive server. It
  reads whole frames (MBAP header + PDU) in both directions and, at random frames, injects:
  ``delay`` (hold the frame, then pass it), ``drop`` (swallow it), ``reset`` (RST the client's
  connection), ``half_open`` (stop forwarding but keep both sockets open: the client hears
  nothing until it gives up and reconnects) or ``corrupt`` (flip one to three bytes of the frame,
  in the MBAP header or in the PDU, before passing it).
- `SerialLineFaults`: sits on a serial line (the simulated interferometer's pty) and offers the
  client a new pty, reached through a symlink (`path`) as a USB adapter's /dev/serial/by-id name
  is. On replies it injects: ``noise`` (flipped, inserted or stray bytes), ``silence`` (a reply
  swallowed) or ``unplug`` (the pty closed and the symlink removed, then after a while a new pty
  behind the same path: the cable pulled and plugged back in).

When faults happen is decided by a `FaultSchedule`: a probability per frame/line, or a mean
interval on a clock (the rig's virtual clock: "every few rig minutes"), drawn from one seeded RNG.
Only loopback addresses are served. Used by tests/faults/ and bench/bench_soak.py.
"""

from __future__ import annotations

import errno
import os
import random
import selectors
import socket
import struct
import tempfile
import threading
import time
import tty
from collections import Counter
from pathlib import Path
from typing import Sequence
from urllib.parse import urlsplit

TCP_KINDS = ("delay", "drop", "reset", "half_open", "corrupt")
LINE_KINDS = ("noise", "silence", "unplug")
MBAP_BYTES = 7  # transaction id, protocol id, length, unit id
MAX_MBAP_LENGTH = 254  # unit id + the longest PDU (253 bytes)


class FaultSchedule:
    """Decides, for each frame that passes, whether to inject a fault and which.

    `rate`: probability per frame (0 = never). Or `every_s` with `clock` (an object with
    `now()`): one fault after an exponentially distributed interval of mean `every_s` on that
    clock, so faults come "every few minutes" of rig time whatever the frame rate. `kinds`: the
    kinds to draw from, uniformly (`weights` optional). `enabled` switches injection off and on
    (setup without faults). Thread-safe; `counts` holds what was injected, per kind."""

    def __init__(self, kinds: Sequence[str], *, seed: int = 0, rate: float = 0.0, every_s: float | None = None,
                 clock=None, weights: Sequence[float] | None = None):
        if every_s is not None and (clock is None or every_s <= 0):
            raise ValueError("every_s needs a clock and must be > 0 seconds")
        if not 0.0 <= rate <= 1.0:
            raise ValueError(f"rate must be a probability 0..1, got {rate}")
        self.kinds = tuple(kinds)
        self.weights = tuple(weights) if weights else None
        self.rng = random.Random(seed)
        self.rate = rate
        self.every_s = every_s
        self.clock = clock
        self.enabled = True
        self.counts: Counter[str] = Counter()
        self.frames = 0
        self._lock = threading.Lock()
        self._next_t = None if every_s is None else clock.now() + self.rng.expovariate(1.0 / every_s)

    def decide(self) -> str | None:
        """The fault to inject on the frame passing now (counted), or None."""
        with self._lock:
            self.frames += 1
            if not self.enabled:
                return None
            if self.every_s is not None:
                now = self.clock.now()
                if now < self._next_t:
                    return None
                self._next_t = now + self.rng.expovariate(1.0 / self.every_s)
            elif not (self.rate and self.rng.random() < self.rate):
                return None
            kind = self.rng.choices(self.kinds, self.weights)[0]
            self.counts[kind] += 1
            return kind

    def uniform(self, lo: float, hi: float) -> float:
        with self._lock:
            return self.rng.uniform(lo, hi)

    def randint(self, lo: int, hi: int) -> int:
        with self._lock:
            return self.rng.randint(lo, hi)

    def randbytes(self, n: int) -> bytes:
        with self._lock:
            return self.rng.randbytes(n)

    @property
    def total(self) -> int:
        with self._lock:
            return sum(self.counts.values())


def corrupt_frame(frame: bytes, pick: FaultSchedule) -> bytes:
    """`frame` with one to three bytes XOR-ed with a non-zero value, all in the MBAP header or
    all in the PDU (chosen at random; the unit id counts as header)."""
    data = bytearray(frame)
    header = pick.randint(0, 1) == 0 or len(data) <= MBAP_BYTES
    lo, hi = (0, min(MBAP_BYTES, len(data)) - 1) if header else (MBAP_BYTES, len(data) - 1)
    for _ in range(pick.randint(1, 3)):
        data[pick.randint(lo, hi)] ^= pick.randint(1, 255)
    return bytes(data)


class _Conn:
    """One proxied connection: the client's socket and the upstream one, with read buffers."""

    def __init__(self, client: socket.socket, upstream: socket.socket):
        self.client, self.upstream = client, upstream
        self.bufs = {client: b"", upstream: b""}
        self.half_open = False
        self.closed = False

    def peer(self, s: socket.socket) -> socket.socket:
        return self.upstream if s is self.client else self.client

    def close(self, reset: bool = False) -> None:
        if self.closed:
            return
        self.closed = True
        if reset:  # linger 0: close() sends RST instead of FIN
            try:
                self.client.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            except OSError:
                pass
        for s in (self.client, self.upstream):
            try:
                s.close()
            except OSError:
                pass


class ModbusFaultProxy:
    """Modbus TCP proxy on 127.0.0.1 to `upstream_url` (tcp://127.0.0.1:PORT), injecting the
    faults `schedule` decides (kinds from TCP_KINDS) on frames in both directions.

    `delay_s`: (min, max) hold of a delayed frame, seconds of real time (pick the max beyond the
    client's attempt timeout so some delays turn into late replies). `start()` returns the URL to
    give the client. One thread per connection (frames in one connection pass in order; a
    delayed frame holds those behind it, as on a congested link)."""

    def __init__(self, upstream_url: str, schedule: FaultSchedule, delay_s: tuple[float, float] = (0.01, 0.3)):
        parts = urlsplit(upstream_url)
        if parts.scheme != "tcp" or parts.hostname not in ("127.0.0.1", "localhost") or not parts.port:
            raise ValueError(f"the fault proxy relays to loopback Modbus TCP only, not {upstream_url!r}")
        self.upstream = (parts.hostname, parts.port)
        self.schedule = schedule
        self.delay_s = delay_s
        self.url = ""
        self.connections = 0
        self._listener: socket.socket | None = None
        self._threads: list[threading.Thread] = []
        self._conns: set[_Conn] = set()
        self._stop = threading.Event()
        self._lock = threading.Lock()

    @property
    def counts(self) -> Counter[str]:
        return self.schedule.counts

    def start(self) -> str:
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._listener.bind(("127.0.0.1", 0))
        self._listener.listen(8)
        self._listener.settimeout(0.1)
        self.url = f"tcp://127.0.0.1:{self._listener.getsockname()[1]}"
        t = threading.Thread(target=self._accept_loop, name="fault-proxy-accept", daemon=True)
        t.start()
        self._threads.append(t)
        return self.url

    def stop(self) -> None:
        self._stop.set()
        with self._lock:
            threads = list(self._threads)
        for t in threads:
            t.join(2.0)
        with self._lock:
            self._threads.clear()
            for c in list(self._conns):
                c.close()
            self._conns.clear()
        if self._listener is not None:
            self._listener.close()
            self._listener = None

    def __enter__(self) -> "ModbusFaultProxy":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def _accept_loop(self) -> None:
        assert self._listener is not None
        while not self._stop.is_set():
            try:
                client, _ = self._listener.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            try:
                upstream = socket.create_connection(self.upstream, timeout=2.0)
            except OSError:
                client.close()
                continue
            for s in (client, upstream):
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                s.setblocking(False)
            conn = _Conn(client, upstream)
            with self._lock:
                self._conns.add(conn)
                self.connections += 1
                # finished connections' threads are dropped, so a day of reconnects holds none
                self._threads = [t for t in self._threads if t.is_alive()]
                t = threading.Thread(target=self._serve, args=(conn,), name="fault-proxy-conn", daemon=True)
                self._threads.append(t)
            t.start()

    def _serve(self, conn: _Conn) -> None:
        sel = selectors.DefaultSelector()
        try:
            sel.register(conn.client, selectors.EVENT_READ)
            sel.register(conn.upstream, selectors.EVENT_READ)
            while not self._stop.is_set() and not conn.closed:
                for key, _ in sel.select(0.1):
                    src: socket.socket = key.fileobj  # type: ignore[assignment]
                    try:
                        data = src.recv(65536)
                    except BlockingIOError:
                        continue
                    except OSError:
                        data = b""
                    if not data:  # one side closed: close the other (a FIN passed on)
                        conn.close()
                        break
                    if conn.half_open:
                        continue  # swallowed: the link is dead but nobody told the ends
                    conn.bufs[src] += data
                    for frame in self._frames(conn, src):
                        if not self._pass(conn, src, frame):
                            break
                    if conn.closed:
                        break
        finally:
            sel.close()
            conn.close()
            with self._lock:
                self._conns.discard(conn)

    @staticmethod
    def _frames(conn: _Conn, src: socket.socket) -> list[bytes]:
        """Complete frames waiting in `src`'s buffer (taken out of it). A header with an
        impossible length (a corrupted frame a peer sent on) is passed on as it is, whole buffer."""
        out: list[bytes] = []
        buf = conn.bufs[src]
        while len(buf) >= MBAP_BYTES:
            length = int.from_bytes(buf[4:6], "big")
            if not 2 <= length <= MAX_MBAP_LENGTH:
                out.append(buf)
                buf = b""
                break
            n = 6 + length
            if len(buf) < n:
                break
            out.append(buf[:n])
            buf = buf[n:]
        conn.bufs[src] = buf
        return out

    def _pass(self, conn: _Conn, src: socket.socket, frame: bytes) -> bool:
        """Forward one frame, or fault it. False when the connection ended (reset, half-open)."""
        kind = self.schedule.decide()
        if kind == "drop":
            return True
        if kind == "reset":
            conn.close(reset=True)
            return False
        if kind == "half_open":
            conn.half_open = True
            return False
        if kind == "delay":
            time.sleep(self.schedule.uniform(*self.delay_s))
        elif kind == "corrupt":
            frame = corrupt_frame(frame, self.schedule)
        return _send_all(conn.peer(src), frame)


def _send_all(s: socket.socket, data: bytes) -> bool:
    view = memoryview(data)
    deadline = time.monotonic() + 2.0
    while view:
        try:
            n = s.send(view)
        except BlockingIOError:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.001)
            continue
        except OSError:
            return False
        view = view[n:]
    return True


class SerialLineFaults:
    """A faulty serial line in front of the serial device at `upstream_path` (the simulated
    interferometer's pty): the client opens `path` (a symlink to a pty of ours) instead.

    Commands pass unchanged; reply lines (terminated by `terminator`) meet the faults
    `schedule` decides (kinds from LINE_KINDS). `unplug_s`: (min, max) seconds of real time the
    port stays away after an unplug. `silence_lines`: (min, max) replies swallowed in a row by a
    silence. `directory`: where the symlink lives (default: a new temporary directory)."""

    def __init__(self, upstream_path: str, schedule: FaultSchedule, *, terminator: bytes = b"\r\n",
                 unplug_s: tuple[float, float] = (0.05, 0.4), silence_lines: tuple[int, int] = (1, 2),
                 directory: str | Path | None = None):
        self.upstream_path = upstream_path
        self.schedule = schedule
        self.terminator = terminator
        self.unplug_s = unplug_s
        self.silence_lines = silence_lines
        self._tmp = None if directory else tempfile.TemporaryDirectory(prefix="station-line-")
        self.path = str(Path(directory or self._tmp.name) / "laser")
        self.plugs = 0  # how many times a pty was put behind `path`
        self._up: int | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._reply = b""
        self._silent_left = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def counts(self) -> Counter[str]:
        return self.schedule.counts

    def start(self) -> str:
        self._up = os.open(self.upstream_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(self._up)
        self._plug()
        self._thread = threading.Thread(target=self._run, name="line-faults", daemon=True)
        self._thread.start()
        return self.path

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(3.0)
            self._thread = None
        self._unplug()
        if self._up is not None:
            os.close(self._up)
            self._up = None
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self) -> "SerialLineFaults":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def _plug(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo or line editing before the client configures the port
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        tmp = self.path + ".new"
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        os.symlink(os.ttyname(slave), tmp)
        os.replace(tmp, self.path)  # the name appears at once, pointing at the new port
        self.plugs += 1

    def _unplug(self) -> None:
        try:
            os.unlink(self.path)
        except FileNotFoundError:
            pass
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None

    def _run(self) -> None:
        while not self._stop.is_set():
            master, up = self._master, self._up
            sel = selectors.DefaultSelector()
            try:
                sel.register(up, selectors.EVENT_READ)
                if master is not None:
                    sel.register(master, selectors.EVENT_READ)
                ready = sel.select(0.05)
            finally:
                sel.close()
            for key, _ in ready:
                fd = key.fd
                try:
                    data = os.read(fd, 4096)
                except BlockingIOError:
                    continue
                except OSError as exc:
                    if exc.errno == errno.EIO:  # no client has the port open: nothing to read
                        time.sleep(0.005)
                        continue
                    raise
                if fd == master:
                    _write_all(up, data)
                else:
                    self._reply += data
                    self._replies()

    def _replies(self) -> None:
        while True:
            end = self._reply.find(self.terminator)
            if end < 0:
                return
            line, self._reply = self._reply[: end + len(self.terminator)], self._reply[end + len(self.terminator):]
            if self._silent_left:
                self._silent_left -= 1
                continue
            kind = self.schedule.decide()
            if kind == "silence":
                self._silent_left = self.schedule.randint(*self.silence_lines) - 1
                continue
            if kind == "unplug":
                self._unplug()
                time.sleep(self.schedule.uniform(*self.unplug_s))
                self._reply = b""  # what the device said meanwhile went nowhere
                self._plug()
                return
            if kind == "noise":
                line = self._noisy(line)
            if self._master is not None:
                _write_all(self._master, line)

    def _noisy(self, line: bytes) -> bytes:
        """A reply hit by line noise: bytes flipped, garbage inserted, or stray bytes before it."""
        s = self.schedule
        how = s.randint(0, 2)
        data = bytearray(line)
        if how == 0:
            for _ in range(s.randint(1, 3)):
                data[s.randint(0, len(data) - 1)] ^= s.randint(1, 255)
        elif how == 1:
            at = s.randint(0, len(data))
            data[at:at] = s.randbytes(s.randint(1, 8))
        else:
            data[0:0] = s.randbytes(s.randint(1, 16))
        return bytes(data)


def _write_all(fd: int | None, data: bytes) -> None:
    if fd is None:
        return
    view = memoryview(data)
    deadline = time.monotonic() + 1.0
    while view:
        try:
            n = os.write(fd, view)
        except BlockingIOError:
            if time.monotonic() > deadline:
                return
            time.sleep(0.001)
            continue
        except OSError:
            return
        view = view[n:]
