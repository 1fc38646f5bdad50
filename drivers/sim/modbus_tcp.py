"""A Modbus TCP server for the simulated and replay drives: MBAP framing and the PDUs a servo
drive serves, answering from a `RegisterHandler`.

Why not pymodbus' server (which still serves the RTU line): per request it builds PDU objects,
runs the simulator's datastore layers and formats log text, 0.13 ms of the 0.19 ms the replay
drive spent per point (bench/bench_replay.py, py-spy, 2026-11-27); this one decodes the few
fields with `struct` and calls the drive model directly, from a thread per connection. What it serves, as the Modbus
Application Protocol v1.1b3 says:

    03 / 04  read holding / input registers (one register space, as the drives map it)
    06       write single register (the reply echoes the request)
    16       write multiple registers (reply: address, count)
    23       read/write multiple registers (the write first, then the read)
    43 / 14  read device identification (basic objects, stream or individual access)

A quantity outside the protocol's limits (read 1..125, write 1..123, function 23's write
1..121, byte count != 2 x quantity) gets exception 03; any other function code exception 01.
A request for a unit id the handler does not know, or one the handler says not to answer (a
merged RTU frame, an unresponsive drive), gets no reply at all, like a bus with nobody there.
A frame whose MBAP protocol id is not 0 is not Modbus and is dropped; a length field outside
2..254 closes the connection (the stream cannot be re-synchronised), as real gateways do.

tests/drivers/test_modbus_tcp_server.py checks it byte for byte against pymodbus' server, and
tests/drivers/test_modbus_peers.py with mbpoll and modbus-tk's client.
"""

from __future__ import annotations

import logging
import socket
import struct
import threading
from typing import Protocol, Sequence

log = logging.getLogger(__name__)

ILLEGAL_FUNCTION = 0x01
ILLEGAL_VALUE = 0x03
DEVICE_FAILURE = 0x04

MAX_READ = 125  # registers a read may ask for (MODBUS Application Protocol 6.3)
MAX_WRITE = 123  # registers a write multiple may carry (6.12)
MAX_RW_WRITE = 121  # registers function 23 may write (6.17)

CONFORMITY_BASIC_INDIVIDUAL = 0x81  # basic identification, stream and individual access


class NoReply(Exception):
    """Raised by a handler for a request that must get no answer at all."""


class FrameError(Exception):
    """A byte stream that is not Modbus TCP (the connection is closed)."""


class RegisterHandler(Protocol):
    """What the server asks the drives. Unit ids are the wire's; a handler raises NoReply for a
    request nobody answers. `function` is the request's function code (23 comes as its write,
    then its read)."""

    def serves(self, unit: int) -> bool:
        """Whether a drive answers at unit id `unit`."""

    def read_registers(self, unit: int, function: int, address: int, count: int) -> list[int] | int:
        """The registers, or a Modbus exception code."""

    def write_registers(self, unit: int, function: int, address: int, values: list[int]) -> int | None:
        """None when applied, or a Modbus exception code (nothing applied)."""

    def device_objects(self, unit: int) -> dict[int, bytes] | None:
        """The unit's identification objects (object id -> bytes), or None when the drive does
        not serve function 43/14 (exception 01)."""


def _exception(function: int, code: int) -> bytes:
    return bytes((function | 0x80, int(code)))


def _registers(words: Sequence[int]) -> bytes:
    return struct.pack(f">B{len(words)}H", 2 * len(words), *words)


def answer_pdu(handler: RegisterHandler, unit: int, pdu: bytes) -> bytes:
    """The reply PDU to request `pdu` of unit id `unit` (raises NoReply for none)."""
    if not handler.serves(unit):
        raise NoReply  # no drive at this unit id, whatever the function
    fc = pdu[0]
    n = len(pdu)
    if fc in (3, 4):
        if n != 5:
            return _exception(fc, ILLEGAL_VALUE)
        address, count = struct.unpack_from(">HH", pdu, 1)
        if not 1 <= count <= MAX_READ:
            return _exception(fc, ILLEGAL_VALUE)
        res = handler.read_registers(unit, fc, address, count)
        return _exception(fc, res) if isinstance(res, int) else bytes((fc,)) + _registers(res)
    if fc == 6:
        if n != 5:
            return _exception(fc, ILLEGAL_VALUE)
        address, value = struct.unpack_from(">HH", pdu, 1)
        res = handler.write_registers(unit, fc, address, [value])
        return _exception(fc, res) if res is not None else bytes(pdu)
    if fc == 16:
        if n < 6:
            return _exception(fc, ILLEGAL_VALUE)
        address, count, nbytes = struct.unpack_from(">HHB", pdu, 1)
        if not 1 <= count <= MAX_WRITE or nbytes != 2 * count or n != 6 + nbytes:
            return _exception(fc, ILLEGAL_VALUE)
        res = handler.write_registers(unit, fc, address, list(struct.unpack_from(f">{count}H", pdu, 6)))
        return _exception(fc, res) if res is not None else struct.pack(">BHH", fc, address, count)
    if fc == 23:
        if n < 10:
            return _exception(fc, ILLEGAL_VALUE)
        r_address, r_count, w_address, w_count, nbytes = struct.unpack_from(">HHHHB", pdu, 1)
        if not (1 <= r_count <= MAX_READ and 1 <= w_count <= MAX_RW_WRITE) or nbytes != 2 * w_count or n != 10 + nbytes:
            return _exception(fc, ILLEGAL_VALUE)
        res = handler.write_registers(unit, fc, w_address, list(struct.unpack_from(f">{w_count}H", pdu, 10)))
        if res is not None:
            return _exception(fc, res)
        words = handler.read_registers(unit, fc, r_address, r_count)
        return _exception(fc, words) if isinstance(words, int) else bytes((fc,)) + _registers(words)
    if fc == 0x2B and n >= 2 and pdu[1] == 0x0E:
        return _device_identification(handler, unit, pdu)
    return _exception(fc, ILLEGAL_FUNCTION)


def _device_identification(handler: RegisterHandler, unit: int, pdu: bytes) -> bytes:
    """Function 43/14: read code 1-3 (stream from `object_id`), 4 (one object)."""
    fc = 0x2B
    if len(pdu) != 4 or pdu[2] not in (1, 2, 3, 4):
        return _exception(fc, ILLEGAL_VALUE)
    read_code, object_id = pdu[2], pdu[3]
    objects = handler.device_objects(unit)
    if objects is None:
        return _exception(fc, ILLEGAL_FUNCTION)
    if read_code == 4:
        if object_id not in objects:
            return _exception(fc, 0x02)
        info = {object_id: objects[object_id]}
    else:  # basic, regular, extended: these drives have only the basic objects
        info = {oid: v for oid, v in objects.items() if oid >= object_id} or dict(objects)
    body = b"".join(bytes((oid, len(v))) + v for oid, v in info.items())
    return bytes((fc, 0x0E, read_code, CONFORMITY_BASIC_INDIVIDUAL, 0, 0, len(info))) + body


def answer_frames(handler: RegisterHandler, buf: bytes) -> tuple[bytes, bytes]:
    """Answer every whole MBAP frame at the start of `buf`: (the replies, the bytes left over,
    an incomplete frame). Raises FrameError for a length field outside 2..254."""
    out = []
    while len(buf) >= 8:
        tid, pid, length = struct.unpack_from(">HHH", buf)
        if not 2 <= length <= 254:
            raise FrameError(f"MBAP length {length} outside 2..254")
        end = 6 + length
        if len(buf) < end:
            break
        unit, pdu = buf[6], buf[7:end]
        buf = buf[end:]
        if pid != 0:
            continue  # not Modbus
        try:
            reply = answer_pdu(handler, unit, pdu)
        except NoReply:
            continue
        except Exception:  # a fault of the simulated drive: the client gets 04, the log the traceback
            log.exception("Modbus TCP: unit %d, function %d failed", unit, pdu[0])
            reply = _exception(pdu[0], DEVICE_FAILURE)
        out.append(struct.pack(">HHHB", tid, 0, len(reply) + 1, unit) + reply)
    return b"".join(out), buf


class MbapServer:
    """Serves `handler` on (host, port): `start()` returns the port, `close()` ends it.

    One thread accepts and one serves each connection, with blocking socket calls: a request
    wakes its thread straight from recv (on an asyncio loop it took the selector, the loop's
    turn and the transport's callbacks, 0.02 ms a request here). The handler is called from
    these threads: it does its own locking.
    """

    def __init__(self, handler: RegisterHandler, host: str, port: int, name: str = "modbus-tcp"):
        self.handler = handler
        self.host, self.port = host, port
        self.name = name
        self._listener: socket.socket | None = None
        self._conns: set[socket.socket] = set()
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()
        self._closing = False

    def start(self) -> int:
        """Listen; returns the port (the free one chosen for port 0). OSError if it cannot."""
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind((self.host, self.port))
            sock.listen(8)
        except OSError:
            sock.close()
            raise
        self._listener = sock
        self._spawn(self._accept, f"{self.name}-accept", sock)
        return sock.getsockname()[1]

    def _spawn(self, target, name: str, *args) -> None:
        t = threading.Thread(target=target, args=args, name=name, daemon=True)
        with self._lock:
            self._threads = [x for x in self._threads if x.is_alive()]
            self._threads.append(t)
        t.start()

    def _accept(self, listener: socket.socket) -> None:
        while True:
            try:
                conn, _ = listener.accept()
            except OSError:
                return  # closed
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                if self._closing:
                    conn.close()
                    return
                self._conns.add(conn)
            self._spawn(self._serve, f"{self.name}-conn", conn)

    def _serve(self, conn: socket.socket) -> None:
        buf = b""
        try:
            while True:
                data = conn.recv(4096)
                if not data:
                    return
                try:
                    replies, buf = answer_frames(self.handler, buf + data if buf else data)
                except FrameError as exc:
                    log.warning("Modbus TCP: %s; closing the connection", exc)
                    return
                if replies:
                    conn.sendall(replies)
        except OSError:
            return  # the peer went away, or close() shut it
        finally:
            with self._lock:
                self._conns.discard(conn)
            conn.close()

    def close(self) -> None:
        """Stop listening and close every connection (clients see the drive close them);
        returns when the threads have ended. Idempotent."""
        with self._lock:
            self._closing = True
            conns = list(self._conns)
            threads = list(self._threads)
        if self._listener is not None:
            try:
                self._listener.shutdown(socket.SHUT_RDWR)  # wakes the accept() (close alone does not)
            except OSError:
                pass
            self._listener.close()
            self._listener = None
        for c in conns:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        for t in threads:
            if t is not threading.current_thread():
                t.join(5.0)
