"""Fuzzing the interferometer's reply parser (drivers/interferometer/protocol.py).

Lines with a correct checksum around random fields (so the field parsers are reached), valid
replies with one byte changed, and random bytes. Property: parsed values that are finite and in
range, or ProtocolError (the client's retry-then-FramingError path) / InstrumentError (an ERR
reply); never another exception. And what the instrument formats, the client parses back.
"""

from __future__ import annotations

import math

from hypothesis import example, given, settings, strategies as st

from drivers.interferometer import protocol as p
from tests.fuzz.budget import examples, fed

AXES = 6
field = st.one_of(
    st.sampled_from(["POS", "ENV", "IDN", "OK", "AVG", "ERR", "CAPN", "CAP", "BEAM", "LOW", "NAN", "nan", "inf", "-inf",
                     "1e400", "1_0", "", " ", "+1", "-0", "0x1", "9" * 400]),
    st.integers(-2, 8).map(str),
    st.floats().map(repr),
    st.text(alphabet=st.characters(min_codepoint=0x20, max_codepoint=0x7E), max_size=10),
)


def framed(fields: list[str]) -> bytes:
    body = ",".join(fields).encode("ascii")
    return body + b"*" + p.checksum(body).encode() + p.TERMINATOR


valid = st.one_of(
    st.builds(p.format_position, st.integers(1, AXES), st.floats(-200, 200), st.sampled_from(p.STATUSES),
              st.floats(0, 100), st.floats(0, 1e6)),
    st.builds(p.format_environment, st.floats(-10, 50), st.floats(500, 1100), st.floats(0, 100),
              st.lists(st.one_of(st.floats(-10, 80), st.just(math.nan)), min_size=AXES, max_size=AXES)),
    st.builds(p.format_error, st.integers(0, 9), st.text(max_size=20)),
)


@st.composite
def flipped(draw) -> bytes:
    line = draw(valid)
    i = draw(st.integers(0, len(line) - 1))
    return line[:i] + bytes([draw(st.integers(0, 255))]) + line[i + 1:]


PARSERS = {
    "identity": lambda f: p.parse_identity(f),
    "position": lambda f: p.parse_position(f, 3),
    "environment": lambda f: p.parse_environment(f, AXES),
    "ok": lambda f: p.parse_ok(f),
    "averaging": lambda f: p.parse_averaging(f),
}
for _name, _axis_args in (("parse_capture_count", (3,)), ("parse_capture_sample", (3, 0)), ("parse_capture_block", (3, 0, 5))):
    if hasattr(p, _name):  # on-the-fly capture replies, where the protocol has them
        PARSERS[_name.removeprefix("parse_")] = lambda f, fn=getattr(p, _name), a=_axis_args: fn(f, *a)


def _finite(*values) -> None:
    for v in values:
        assert isinstance(v, (int, float)) and math.isfinite(v), values


@settings(max_examples=examples(400))
@given(st.one_of(st.lists(field, min_size=1, max_size=11).map(framed), flipped(), valid, st.binary(max_size=80)))
@example(b"POS,3,+1.000000000,OK,50.0,1.0*00\r\n")  # bad checksum
@example(framed(["POS", "3", "1e400", "OK", "50", "1"]))
@example(framed(["ENV", "20", "1013", "50"] + ["NAN"] * AXES))
@example(framed(["ERR"]))
@example(framed(["POS", "9" * 5000, "1", "OK", "50", "1"]))
def test_reply_parsers_fuzzed(line):
    try:
        fields = p.split_reply(line)
    except p.ProtocolError:
        fed("interferometer reply (split_reply)", refused=True)
        return
    fed("interferometer reply (split_reply)")
    try:
        p.raise_if_error(fields, "POS? 3", "/dev/pts/9")
    except p.InstrumentError as exc:
        assert "/dev/pts/9" in str(exc) and isinstance(exc.code, int)
    for name, parse in PARSERS.items():
        try:
            out = parse(fields)
        except p.ProtocolError:
            fed("interferometer reply (parse_*)", refused=True)
            continue
        fed("interferometer reply (parse_*)")
        if name == "position":
            assert out.axis == 3 and out.status in p.STATUSES and 0 <= out.signal_pct <= 100
            _finite(out.position_mm, out.signal_pct, out.t_s)
        elif name == "environment":
            _finite(out.air_temp_c, out.air_pressure_hpa, out.humidity_pct)
            assert len(out.material_temp_c) == AXES and not any(math.isinf(t) for t in out.material_temp_c)
        elif name == "averaging":
            _finite(out)
            assert 0 <= out <= p.MAX_AVERAGING_S


@settings(max_examples=examples(100))
@given(st.integers(1, AXES), st.floats(-200, 200), st.sampled_from(p.STATUSES), st.floats(0, 100), st.floats(0, 1e6))
def test_position_round_trip(axis, position_mm, status, signal_pct, t_s):
    got = p.parse_position(p.split_reply(p.format_position(axis, position_mm, status, signal_pct, t_s)), axis)
    fed("interferometer reply round trip")
    assert abs(got.position_mm - position_mm) <= 5e-10 and got.status == status
    assert abs(got.signal_pct - signal_pct) <= 0.05 and abs(got.t_s - t_s) <= 5e-7
