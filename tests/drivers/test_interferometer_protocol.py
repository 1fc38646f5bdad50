"""The interferometer protocol byte for byte: checksum and framing rules, the documented example,
and the exact commands the client sends (a scripted peer on a real pty, PyMeasure-style
`expected_protocol`: the test states the exchange and fails if the script is not consumed
exactly)."""

from __future__ import annotations

import math
import os
import random
import re
import select
import threading
import time
import tty
from contextlib import contextmanager
from pathlib import Path

import pytest

from drivers.errors import BeamBreak, CommTimeout, FramingError
from drivers.interferometer import protocol as p
from drivers.interferometer.client import SerialInterferometer

DOC = Path(__file__).resolve().parents[2] / "docs" / "interferometer-protocol.md"


# -- checksum and framing -------------------------------------------------------------------


def test_checksum_matches_a_published_nmea_sentence():
    # a GPS sentence with its published checksum (NMEA 0183: XOR of the bytes between $ and *)
    body = b"GPGGA,092750.000,5321.6802,N,00630.3372,W,1,8,1.03,61.7,M,55.2,M,,"
    assert p.checksum(body) == "76"


@pytest.mark.parametrize("n", [0, 1, 2, 3, 7, 8, 9, 40, 63, 64, 65, 255])
def test_checksum_is_the_xor_of_every_byte(n):
    rng = random.Random(n)
    for _ in range(20):
        body = bytes(rng.randrange(256) for _ in range(n))
        value = 0
        for byte in body:  # the definition, one byte at a time
            value ^= byte
        assert p.checksum(body) == f"{value:02X}"


def test_frame_and_split_round_trip():
    line = p.frame_reply("POS", 3, "+1.000000000", "OK", "90.0", "1.500000")
    assert line == b"POS,3,+1.000000000,OK,90.0,1.500000*" + p.checksum(line[: line.index(b"*")]).encode() + b"\r\n"
    assert p.split_reply(line) == ["POS", "3", "+1.000000000", "OK", "90.0", "1.500000"]


@pytest.mark.parametrize(
    "line, reason",
    [
        (b"", "empty reply"),
        (b"OK*04", "not terminated"),
        (b"OK*04\n", "not terminated"),
        (b"OK\r\n", "no '\\*HH' checksum"),
        (b"OK*4\r\n", "not two uppercase hex digits"),
        (b"OK*0a\r\n", "not two uppercase hex digits"),
        (b"OK*05\r\n", "bad checksum: reply says 05, computed 04"),
        (b"O\xffK*04\r\n", "non-printable or non-ASCII"),
        (b"OK\x00*04\r\n", "non-printable"),
    ],
)
def test_malformed_lines_are_rejected_with_the_reason(line, reason):
    with pytest.raises(p.ProtocolError, match=reason):
        p.split_reply(line)


def _pos_axis_1(fields):
    return p.parse_position(fields, 1)


def _env_1_axis(fields):
    return p.parse_environment(fields, 1)


@pytest.mark.parametrize(
    "parse, fields, reason",
    [
        (_pos_axis_1, ["POS", "2", "+1.0", "OK", "90.0", "1.0"], "reply is for axis 2, asked for axis 1"),
        (_pos_axis_1, ["POS", "1", "+1.0", "OK", "90.0"], "POS reply has 5 fields, expected 6"),
        (_pos_axis_1, ["POS", "1", "abc", "OK", "90.0", "1.0"], r"field 2 \(position_mm\) is 'abc', not a number"),
        (_pos_axis_1, ["POS", "1", "nan", "OK", "90.0", "1.0"], "not a finite number"),
        (_pos_axis_1, ["POS", "1", "+1.0", "MAYBE", "90.0", "1.0"], r"field 3 \(status\) is 'MAYBE'"),
        (_pos_axis_1, ["POS", "1", "+1.0", "OK", "190.0", "1.0"], "is 190.0, outside 0..100"),
        (_pos_axis_1, ["AVG", "0.0"], "expected a POS reply, got 'AVG'"),
        (_env_1_axis, ["ENV", "20.0", "1013.0", "45.0"], "0 material temperatures, expected 1"),
        (_env_1_axis, ["ENV", "20.0", "1013.0", "45.0", "hot"], "material_temp_c of axis 1.*'hot'"),
        (p.parse_identity, ["IDN", "x"], "IDN reply has 2 fields, expected 5"),
        (p.parse_averaging, ["AVG", "11.0"], r"averaging_s\) is 11.0, outside 0..10"),
        (p.parse_ok, ["OK", "1"], "OK reply has 2 fields, expected 1"),
    ],
)
def test_malformed_fields_are_rejected_with_the_field_named(parse, fields, reason):
    with pytest.raises(p.ProtocolError, match=reason):
        parse(fields)


def test_the_documented_example_exchange_is_valid():
    """Every reply line in the protocol document carries a correct checksum and parses."""
    text = DOC.read_text()
    replies = re.findall(r"^\s+< (.*)\\r\\n$", text, flags=re.MULTILINE)
    assert len(replies) >= 7
    for reply in replies:
        fields = p.split_reply(reply.encode("ascii") + b"\r\n")
        assert fields[0] in {"IDN", "OK", "AVG", "POS", "ENV", "ERR", "COMP", "CAPN", "CAP"}, reply
        if fields[0] == "COMP":
            p.parse_compensation(fields)
        if fields[0] == "CAPN":  # on-the-fly capture (docs/onthefly.md)
            p.parse_capture_count(fields, int(fields[1]))
        if fields[0] == "CAP":
            p.parse_capture_sample(fields, int(fields[1]), int(fields[2]))
    table = re.findall(r"`(ERR,\d,[^`]*\*[0-9A-F]{2})`", text)
    assert len(table) == 4
    for reply in table:
        p.split_reply(reply.encode("ascii") + b"\r\n")


# -- the exact exchange -----------------------------------------------------------------------


class ScriptedPeer:
    """The far end of a pty that expects exact command bytes and answers from a script.

    `script` is a list of (expected_command, reply) pairs; reply None = stay silent; a reply
    given as a tuple of chunks is written piece by piece `chunk_gap_s` apart (a slow line). An
    optional third element delays the reply by that many seconds (an instrument averaging).
    Fails (in the test thread, on exit) if a command differs, if the script is not consumed, or
    if the client sends anything more.
    """

    def __init__(self, script: list[tuple], wait_s: float = 2.0):
        self.script = list(script)
        self.wait_s = wait_s
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.port = os.ttyname(self.slave)
        self.problems: list[str] = []
        self.consumed = 0
        self.replied = threading.Semaphore(0)  # released after each reply is written
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _receive(self, count: int) -> bytes:
        data = b""
        deadline = time.monotonic() + self.wait_s
        while len(data) < count:
            ready, _, _ = select.select([self.master], [], [], max(0.0, deadline - time.monotonic()))
            if not ready:
                break
            data += os.read(self.master, count - len(data))
        return data

    chunk_gap_s = 0.02

    def _run(self) -> None:
        for expected, reply, *delay_s in self.script:
            got = self._receive(len(expected))
            if not got:
                return  # the client stopped talking: reported as an unconsumed script
            if got != expected:
                self.problems.append(f"step {self.consumed + 1}: expected {expected!r}, got {got!r}")
                return
            self.consumed += 1
            # delays are the instrument's behaviour (the stimulus), not the test waiting
            if delay_s:
                time.sleep(delay_s[0])
            chunks = reply if isinstance(reply, tuple) else () if reply is None else (reply,)
            for i, chunk in enumerate(chunks):
                if i:
                    time.sleep(self.chunk_gap_s)
                os.write(self.master, chunk)
            if chunks:
                self.replied.release()

    def __enter__(self) -> "ScriptedPeer":
        self._thread.start()
        return self

    def __exit__(self, exc_type, *exc: object) -> None:
        self._thread.join(timeout=self.wait_s + 1.0)
        try:
            ready, _, _ = select.select([self.master], [], [], 0.0)
            extra = os.read(self.master, 1024) if ready else b""
        finally:
            os.close(self.master)
            os.close(self.slave)
        if exc_type is None:  # plain raises: pytest's assert rewriting would reformat the text
            if self.problems:
                raise AssertionError("; ".join(self.problems))
            if self.consumed != len(self.script):
                raise AssertionError(f"only {self.consumed} of {len(self.script)} steps consumed")
            if extra:
                raise AssertionError(f"client sent more than the script: {extra!r}")


@contextmanager
def expected_protocol(script, peer_wait_s: float = 2.0, **client_kw):
    """A SerialInterferometer connected to a ScriptedPeer following `script`."""
    with ScriptedPeer(script, wait_s=peer_wait_s) as peer:
        laser = SerialInterferometer(peer.port, **{"timeout_s": 0.2, "retries": 1, **client_kw})
        try:
            yield laser
        finally:
            laser.close()


def test_identity_exchange():
    with expected_protocol([(b"*IDN?\n", b"IDN,Acme,LI-6,12345,2.1*6B\r\n")]) as laser:
        assert p.checksum(b"IDN,Acme,LI-6,12345,2.1") == "6B"
        assert laser.identity() == "Acme,LI-6,12345,2.1"


def test_first_read_asks_the_averaging_time_once_then_only_positions():
    script = [
        (b"AVG?\n", p.frame_reply("AVG", "0.000")),
        (b"POS? 2\n", p.frame_reply("POS", 2, "+0.123456789", "OK", "91.5", "3.250000")),
        (b"POS? 6\n", p.frame_reply("POS", 6, "-1.000000001", "OK", "88.0", "3.500000")),
    ]
    with expected_protocol(script) as laser:
        r2 = laser.read(2)
        r6 = laser.read(6)
        assert laser.transactions == 3
    assert (r2.axis, r2.position_mm, r2.beam_ok, r2.signal_pct, r2.t_s) == (2, 0.123456789, True, 91.5, 3.25)
    assert (r6.axis, r6.position_mm) == (6, -1.000000001)


def test_set_averaging_and_zero_exchanges():
    script = [
        (b"AVG 0.250\n", b"OK*04\r\n"),
        (b"POS? 1\n", p.frame_reply("POS", 1, "+0.000000000", "OK", "90.0", "0.250000")),
        (b"ZERO 4\n", b"OK*04\r\n"),
    ]
    with expected_protocol(script) as laser:
        laser.set_averaging(0.25)
        laser.read(1)  # averaging known from AVG: no AVG? query
        laser.zero(4)


def test_environment_exchange():
    script = [(b"ENV?\n", p.frame_reply("ENV", "20.012", "1013.31", "45.2", "20.000", "NAN"))]
    with expected_protocol(script, axes=2) as laser:
        env = laser.environment()
    assert (env.air_temp_c, env.air_pressure_hpa, env.humidity_pct) == (20.012, 1013.31, 45.2)
    assert env.material_temp_of(1) == 20.0 and math.isnan(env.material_temp_of(2))


def test_environment_of_another_axis_count_is_asked_again_then_a_framing_error():
    reply = p.frame_reply("ENV", "20.012", "1013.31", "45.2", "20.000", "NAN")
    with expected_protocol([(b"ENV?\n", reply), (b"ENV?\n", reply)], axes=6) as laser:
        with pytest.raises(FramingError, match="2 material temperatures, expected 6"):
            laser.environment()


def test_garbled_reply_is_asked_again_with_the_same_bytes():
    good = p.frame_reply("POS", 3, "+5.000000000", "OK", "90.0", "1.000000")
    script = [
        (b"AVG?\n", p.frame_reply("AVG", "0.000")),
        (b"POS? 3\n", good.replace(b"+5.0", b"+5.1")),  # one character changed: checksum fails
        (b"POS? 3\n", good),
    ]
    with expected_protocol(script) as laser:
        assert laser.read(3).position_mm == 5.0
        assert (laser.transactions, laser.retried) == (3, 1)


def test_late_reply_for_another_axis_is_not_taken_for_the_answer():
    script = [
        (b"AVG?\n", p.frame_reply("AVG", "0.000")),
        (b"POS? 3\n", p.frame_reply("POS", 2, "+9.000000000", "OK", "90.0", "1.000000")),
        (b"POS? 3\n", p.frame_reply("POS", 3, "+3.000000000", "OK", "90.0", "1.100000")),
    ]
    with expected_protocol(script) as laser:
        assert laser.read(3).position_mm == 3.0


def test_reply_arriving_after_its_timeout_does_not_answer_the_next_command():
    late_idn = p.frame_reply("IDN", "Acme", "LI-6", "1", "2.1")
    script = [
        (b"*IDN?\n", late_idn, 0.1),  # answered after the client gave up (timeout 0.05 s)
        (b"AVG?\n", p.frame_reply("AVG", "0.000")),
        (b"POS? 1\n", p.frame_reply("POS", 1, "+1.000000000", "OK", "90.0", "1.000000")),
    ]
    with ScriptedPeer(script) as peer:
        laser = SerialInterferometer(peer.port, timeout_s=0.05, retries=0)
        try:
            with pytest.raises(CommTimeout):
                laser.identity()
            assert peer.replied.acquire(timeout=2.0)  # the stale IDN line now waits in the port
            assert laser.read(1).position_mm == 1.0  # retries=0: only right if it was discarded
        finally:
            laser.close()


def test_beam_and_refusals_are_not_retried():
    script = [
        (b"AVG?\n", p.frame_reply("AVG", "0.000")),
        (b"POS? 1\n", p.frame_reply("POS", 1, "+0.000000000", "BEAM", "0.0", "1.000000")),
        (b"ZERO 2\n", p.format_error(p.ERR_BAD_AXIS, "axis 2 not fitted")),
    ]
    with expected_protocol(script) as laser:
        with pytest.raises(BeamBreak, match="axis 1 .*beam interrupted"):
            laser.read(1)
        with pytest.raises(p.InstrumentError, match="refused 'ZERO 2': bad axis .*axis 2 not fitted"):
            laser.zero(2)


def test_silence_is_retried_then_reported_with_port_and_timeout():
    script = [(b"*IDN?\n", None), (b"*IDN?\n", None)]
    with expected_protocol(script, timeout_s=0.05, retries=1) as laser:
        t0 = time.monotonic()
        with pytest.raises(CommTimeout, match=rf"{laser.port} did not answer '\*IDN\?' within 0.05 s \(2 attempts"):
            laser.identity()
        assert 0.1 <= time.monotonic() - t0 < 0.1 + 0.12


def test_long_averaging_extends_the_wait_for_a_position():
    """With 0.15 s averaging the instrument answers after 0.15 s, in two pieces; a 0.1 s
    timeout must not fire, and the pieces make one line."""
    reply = p.frame_reply("POS", 1, "+0.000000000", "OK", "90.0", "0.150000")
    script = [(b"AVG 0.150\n", b"OK*04\r\n"), (b"POS? 1\n", (reply[:10], reply[10:]), 0.15)]
    with expected_protocol(script, timeout_s=0.1, retries=0) as laser:
        laser.set_averaging(0.15)
        assert laser.read(1).t_s == 0.15


def test_the_scripted_peer_itself_fails_on_any_deviation():
    """The harness above can fail: a different command, an unconsumed script, extra bytes."""
    quick = {"timeout_s": 0.05, "retries": 0, "peer_wait_s": 0.2}
    with pytest.raises(AssertionError, match=re.escape("expected b'ZERO 1\\n', got b'ZERO 2\\n'")):
        with expected_protocol([(b"ZERO 1\n", b"OK*04\r\n")], **quick) as laser:
            with pytest.raises(CommTimeout):
                laser.zero(2)
    with pytest.raises(AssertionError, match="only 0 of 1 steps consumed"):
        with expected_protocol([(b"*IDN?\n", b"IDN,a,b,c,d*00\r\n")], **quick):
            pass
    with pytest.raises(AssertionError, match=re.escape("client sent more than the script: b'ZERO 3\\n'")):
        with expected_protocol([(b"ZERO 3\n", b"OK*04\r\n")], **quick) as laser:
            laser.zero(3)
            with pytest.raises(CommTimeout):
                laser.zero(3)
