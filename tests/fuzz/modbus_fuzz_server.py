"""A Modbus TCP server on 127.0.0.1 that answers each request as the test tells it: a correct
reply, or garbage of one kind (see REPLIES). For fuzzing the station's Modbus client.

Each request takes the next reply kind from `plan` (a correct reply once the plan is used up).
`valid_sent` holds the register values of every correct read reply sent, so a test can check
that a value the client returned is one the drive really sent.
"""

from __future__ import annotations

import random
import select
import socket
import struct
import threading
import time
from collections import deque

REPLIES = (
    "valid",  # a correct reply
    "garbled",  # random bytes
    "short",  # a correct reply cut short (the connection then idles)
    "wrong_function",  # a well-formed reply with another function code
    "wrong_tid",  # a correct reply for another transaction id
    "wrong_unit",  # a correct reply from another unit id
    "exception",  # a Modbus exception reply (function | 0x80, a random code)
    "bad_count",  # byte count disagreeing with the data / the request
    "bad_length",  # MBAP length field disagreeing with the PDU
    "silence",  # no reply (the client times out)
    "late",  # a correct reply after the client gave up waiting
    "close",  # the connection closed instead of a reply
    "extra",  # a correct reply followed by junk
)


class FuzzModbusServer:
    def __init__(self, seed: int = 0, late_s: float = 0.3):
        self.plan: deque[str] = deque()
        self.valid_sent: list[list[int]] = []
        self.requests = 0
        self.replies: dict[str, int] = {}
        self.late_s = late_s
        self._rng = random.Random(seed)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._sock.bind(("127.0.0.1", 0))
        self._sock.listen(4)
        self.port = self._sock.getsockname()[1]
        self._stop = threading.Event()
        self._loops = 0  # rounds of the serving loop (wait_idle)
        self._conns: list[socket.socket] = []
        self._thread = threading.Thread(target=self._serve, name="fuzz-modbus", daemon=True)
        self._thread.start()

    def reset(self, plan, seed: int) -> None:
        self.plan = deque(plan)
        self.valid_sent = []
        self._rng.seed(seed)

    def wait_idle(self) -> None:
        """Return once the serving loop has come round twice: a late reply it was holding back
        (the thread sleeps for it) has been sent, so the next request is answered at once."""
        start = self._loops
        while self._loops < start + 2 and self._thread.is_alive():
            time.sleep(0.01)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5)
        for c in self._conns:
            c.close()
        self._sock.close()

    # -- serving ---------------------------------------------------------------------------
    def _serve(self) -> None:
        bufs: dict[socket.socket, bytes] = {}
        while not self._stop.is_set():
            self._loops += 1
            ready, _, _ = select.select([self._sock, *bufs], [], [], 0.05)
            for s in ready:
                if s is self._sock:
                    conn, _ = self._sock.accept()
                    bufs[conn] = b""
                    self._conns.append(conn)
                    continue
                try:
                    data = s.recv(4096)
                except OSError:
                    data = b""
                if not data:
                    bufs.pop(s, None)
                    s.close()
                    continue
                bufs[s] += data
                while len(bufs.get(s, b"")) >= 7:
                    length = struct.unpack(">H", bufs[s][4:6])[0]
                    if len(bufs[s]) < 6 + length:
                        break
                    frame, bufs[s] = bufs[s][: 6 + length], bufs[s][6 + length:]
                    if not self._answer(s, frame):
                        bufs.pop(s, None)
                        s.close()
                        break

    def _answer(self, s: socket.socket, frame: bytes) -> bool:
        """Reply to one request frame; False when the connection was closed."""
        tid, _pid, _length, unit, fc = struct.unpack(">HHHBB", frame[:8])
        self.requests += 1
        kind = self.plan.popleft() if self.plan else "valid"
        self.replies[kind] = self.replies.get(kind, 0) + 1
        rng = self._rng
        if fc == 3:
            _addr, count = struct.unpack(">HH", frame[8:12])
            regs = [rng.randrange(0x10000) for _ in range(count)]
            pdu = bytes([fc, 2 * count]) + b"".join(struct.pack(">H", r) for r in regs)
        elif fc in (6, 16):
            regs = None
            pdu = frame[7:12]
        else:
            regs = None
            pdu = bytes([fc | 0x80, 1])

        def mbap(p: bytes, t: int = tid, u: int = unit, length: int | None = None) -> bytes:
            return struct.pack(">HHHB", t, 0, len(p) + 1 if length is None else length, u) + p

        good = mbap(pdu)
        if kind == "valid" or kind == "late" or kind == "extra":
            if regs is not None:
                self.valid_sent.append(regs)
        if kind == "valid":
            out = good
        elif kind == "garbled":
            out = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 40)))
        elif kind == "short":
            out = good[: rng.randrange(1, len(good))]
        elif kind == "wrong_function":
            out = mbap(bytes([rng.choice([1, 2, 4, 5, 15, 23, 43])]) + pdu[1:])
        elif kind == "wrong_tid":
            out = mbap(pdu, t=(tid + rng.randrange(1, 0xFFFF)) & 0xFFFF)
        elif kind == "wrong_unit":
            out = mbap(pdu, u=(unit + rng.randrange(1, 255)) & 0xFF)
        elif kind == "exception":
            out = mbap(bytes([fc | 0x80, rng.choice([1, 2, 3, 4, 6, 11, 0, 99, 255])]))
        elif kind == "bad_count":
            out = mbap(bytes([fc, (pdu[1] + rng.randrange(1, 255)) & 0xFF]) + pdu[2:]) if fc == 3 else mbap(pdu[:3])
        elif kind == "bad_length":
            out = mbap(pdu, length=rng.choice([0, 1, 2, len(pdu) + 5, 300]))
        elif kind == "silence":
            return True
        elif kind == "late":
            time.sleep(self.late_s)
            out = good
        elif kind == "close":
            return False
        else:  # extra
            out = good + bytes(rng.randrange(256) for _ in range(rng.randrange(1, 20)))
        try:
            s.sendall(out)
        except OSError:
            return False
        return True
