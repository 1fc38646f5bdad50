"""Fuzzing the interferometer client (drivers/interferometer/client.py) over a real pty: an
instrument that answers each command line with what the test draws -- a correct reply, a line
with one byte changed, random bytes, half a line, two lines, a line far too long, an ERR reply,
a reply to another axis, or silence.

Property: each call returns what the instrument sent in a correct reply, or raises a
DriverError (CommTimeout, FramingError, BeamBreak, InstrumentError); never another exception,
never a hang; and after any of it the next exchange gets its own reply.
"""

from __future__ import annotations

import os
import random
import select
import threading
import tty
from collections import deque

import pytest
from hypothesis import example, given, settings, strategies as st

from drivers.errors import DriverError
from drivers.interferometer import protocol as p
from drivers.interferometer.client import SerialInterferometer
from tests.fuzz.budget import INPUTS, examples, fed

KINDS = ("valid", "flipped", "noise", "half", "two_lines", "too_long", "err", "other_axis", "silence", "beam")


class FuzzInstrument:
    """Answers on the master side of a pty, one drawn kind per command line."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.port = os.ttyname(self.slave)
        self.plan: deque[str] = deque()
        self.valid_positions: list[float] = []
        self.rng = random.Random(0)
        self.lines = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="fuzz-laser", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5)
        os.close(self.master)
        os.close(self.slave)

    def _good(self, cmd: str, args: list[str]) -> bytes:
        rng = self.rng
        if cmd == "POS?":
            pos = round(rng.uniform(-100, 100), 9)
            self.valid_positions.append(pos)
            return p.format_position(int(args[0]) if args and args[0].isdigit() else 1, pos, "OK", 80.0, rng.uniform(0, 1e4))
        if cmd == "ENV?":
            return p.format_environment(20.0, 1013.0, 45.0, [20.1] * 6)
        if cmd == "AVG?":
            return p.frame_reply("AVG", "0.000")
        if cmd == "*IDN?":
            return p.frame_reply("IDN", "Fuzz", "Laser", "1", "0.1")
        return p.frame_reply("OK")

    def _serve(self) -> None:
        buf = b""
        while not self._stop.is_set():
            if not select.select([self.master], [], [], 0.05)[0]:
                continue
            try:
                buf += os.read(self.master, 4096)
            except OSError:
                return
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                self.lines += 1
                cmd, args = p.parse_command(line)
                kind = self.plan.popleft() if self.plan else "valid"
                rng = self.rng
                good = self._good(cmd, args)
                out = {
                    "valid": good,
                    "flipped": None,
                    "noise": bytes(rng.randrange(256) for _ in range(rng.randrange(1, 60))),
                    "half": good[: max(1, len(good) // 2)],
                    "two_lines": good + good,
                    "too_long": b"A" * 300 + b"\r\n",
                    "err": p.format_error(rng.choice([1, 2, 3, 4, 5, 99]), "no"),
                    "other_axis": p.format_position(9, 1.0, "OK", 80.0, 1.0),
                    "silence": b"",
                    "beam": p.format_position(int(args[0]) if args and args[0].isdigit() else 1, 0.0, "BEAM", 3.0, 1.0),
                }[kind]
                if kind == "flipped":
                    i = rng.randrange(len(good))
                    out = good[:i] + bytes([rng.randrange(256)]) + good[i + 1:]
                if kind not in ("valid", "two_lines") and cmd == "POS?" and self.valid_positions:
                    self.valid_positions.pop()  # that position was not sent in a correct reply
                if out:
                    os.write(self.master, out)


@pytest.fixture(scope="module")
def instrument():
    inst = FuzzInstrument()
    yield inst
    inst.stop()
    INPUTS["interferometer pty: command lines answered"] += inst.lines


@settings(max_examples=examples(60), deadline=10000)
@given(st.lists(st.one_of(st.sampled_from([k for k in KINDS if k != "silence"]), st.sampled_from(KINDS)), max_size=5),
       st.lists(st.sampled_from(["read", "environment", "identity", "averaging"]), min_size=1, max_size=3),
       st.integers(0, 2**16))
@example(["valid", "two_lines"], ["read"], 0)  # the first of two correct lines is the answer
def test_client_against_a_noisy_instrument(instrument, plan, calls, seed):
    instrument.plan = deque(plan)
    instrument.rng.seed(seed)
    instrument.valid_positions = []
    laser = SerialInterferometer(instrument.port, timeout_s=0.15, retries=1)
    try:
        for call in calls:
            try:
                if call == "read":
                    r = laser.read(3)
                    assert r.axis == 3 and r.beam_ok and r.position_mm in instrument.valid_positions, r
                elif call == "environment":
                    env = laser.environment()
                    assert env.air_temp_c == 20.0 and len(env.material_temp_c) == 6
                elif call == "identity":
                    assert laser.identity() == "Fuzz,Laser,1,0.1"
                else:
                    assert laser.averaging() == 0.0
            except DriverError as exc:
                fed("interferometer reply over a pty (client call)", refused=True)
                assert instrument.port in str(exc), exc
            else:
                fed("interferometer reply over a pty (client call)")
        instrument.plan.clear()
        instrument.valid_positions = []
        r = laser.read(3)  # recovers: the next exchange gets its own reply
        assert r.position_mm == instrument.valid_positions[-1]
    finally:
        laser.close()
