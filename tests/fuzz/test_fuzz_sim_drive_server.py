"""Fuzzing the simulated drive's Modbus TCP server (drivers/sim/modbus_tcp.py) and the drive
model behind it.

Streams of MBAP frames around random PDUs (the functions the drive serves and others, addresses
in and around the register map, any quantity, any values), whole frames cut at random places,
and random bytes. Properties: `answer_frames` refuses only with FrameError; every reply is a
well-formed frame for a request that was sent (protocol id 0, its transaction and unit id, its
function or that function + 0x80 with a Modbus exception code); nobody at an unknown unit id
answers; and whatever was written, the simulated leg never stands outside the soft limits.
"""

from __future__ import annotations

import struct
import threading

from hypothesis import given, strategies as st

from drivers.clock import VirtualClock
from drivers.modbus.profile import DriveProfile
from drivers.sim.drive_server import SimDriveServer, _Units
from drivers.sim.modbus_tcp import FrameError, answer_frames
from drivers.plant.leg import LegPlant, default_leg_configs
from tests.fuzz.budget import fed

PROFILE = DriveProfile.load(None)
LEGS = (1, 2)
SIZE = max(r.end for r in PROFILE.registers.values()) + 64
CW = PROFILE.registers["controlword"].address
TARGET = PROFILE.registers["target_position"]
EXCEPTIONS = {1, 2, 3, 4, 6}

word = st.integers(0, 0xFFFF)
address = st.one_of(st.integers(0, SIZE), st.sampled_from([CW, TARGET.address, TARGET.address + 1]), st.integers(0, 0xFFFF))
count = st.one_of(st.integers(0, 3), st.integers(0, 130))


@st.composite
def pdu(draw) -> bytes:
    fc = draw(st.sampled_from([3, 4, 6, 16, 23, 43, 1, 5, 8, 17, 0, 0x83, 255]))
    if fc in (3, 4, 1):
        return struct.pack(">BHH", fc, draw(address), draw(count))
    if fc in (6, 5, 8):
        return struct.pack(">BHH", fc, draw(address), draw(word))
    if fc == 16:
        values = draw(st.lists(word, max_size=8))
        n = draw(st.one_of(st.just(len(values)), count))
        return struct.pack(f">BHHB{len(values)}H", fc, draw(address), n, draw(st.one_of(st.just(2 * len(values)), st.integers(0, 255))), *values)
    if fc == 23:
        values = draw(st.lists(word, max_size=8))
        return struct.pack(f">BHHHHB{len(values)}H", fc, draw(address), draw(count), draw(address),
                           draw(st.one_of(st.just(len(values)), count)), 2 * len(values), *values)
    if fc == 43:
        return bytes([fc, draw(st.sampled_from([14, 13])), draw(st.integers(0, 8)), draw(st.integers(0, 5))])
    return bytes([fc]) + draw(st.binary(max_size=6))


def frame(tid: int, unit: int, body: bytes, pid: int = 0) -> bytes:
    return struct.pack(">HHHB", tid, pid, len(body) + 1, unit) + body


def moves(target_mm: float) -> list[bytes]:
    """Enable, then a set-point to `target_mm` (possibly beyond the soft limits)."""
    raw = round(target_mm / TARGET.scale)
    raw = max(-(1 << 31), min(raw, (1 << 31) - 1))
    words = list(struct.unpack(">2H", struct.pack(">i", raw)))
    out = [struct.pack(">BHH", 6, CW, v) for v in (0x06, 0x07, 0x0F)]
    out.append(struct.pack(">BHHB2H", 16, TARGET.address, 2, 4, *words))
    out.append(struct.pack(">BHH", 6, CW, 0x1F))
    return out


stream = st.lists(
    st.one_of(
        st.tuples(st.sampled_from([1, 2, 0, 9]), pdu(), st.sampled_from([0, 0, 0, 1])),
        st.tuples(st.sampled_from(LEGS), st.floats(-1e4, 1e4).map(moves), st.just(0)),
    ),
    min_size=1, max_size=12,
)


def _drive() -> tuple[SimDriveServer, _Units]:
    plants = {leg: LegPlant(cfg, seed=leg) for leg, cfg in zip(LEGS, default_leg_configs(0, len(LEGS)))}
    server = SimDriveServer(plants, VirtualClock(0.0), PROFILE, lock=threading.RLock())
    return server, _Units(server)


@given(stream, st.lists(st.integers(1, 40), max_size=4))
def test_replies_are_well_formed_and_the_leg_stays_within_its_limits(items, cuts):
    server, units = _drive()
    requests: dict[int, tuple[int, int]] = {}  # tid -> (unit, function) of the frames sent with pid 0
    data = b""
    tid = 0
    for unit, body, pid in items:
        for part in body if isinstance(body, list) else [body]:
            tid += 1
            data += frame(tid, unit, part, pid)
            if pid == 0:
                requests[tid] = (unit, part[0])
    # the stream as a client might send it: in pieces
    pieces, at = [], 0
    for c in cuts:
        pieces.append(data[at : at + c])
        at += c
    pieces.append(data[at:])
    replies, rest = b"", b""
    for piece in pieces:
        out, rest = answer_frames(units, rest + piece)
        replies += out
    fed("simulated drive: Modbus TCP frames")
    assert rest == b""
    while replies:
        r_tid, r_pid, length, r_unit = struct.unpack_from(">HHHB", replies)
        body, replies = replies[7 : 6 + length], replies[6 + length :]
        assert r_pid == 0 and r_tid in requests and len(body) == length - 1
        unit, fc = requests.pop(r_tid)
        assert r_unit == unit and unit in LEGS  # nobody answers at unit 0 or 9
        if body[0] == (fc | 0x80) and fc < 0x80:
            assert len(body) == 2 and body[1] in EXCEPTIONS
        else:
            assert body[0] == fc
    lim = PROFILE.limits
    for leg in LEGS:
        nut = server._models[leg].nut_mm
        assert lim.soft_min_mm - 1e-9 <= nut <= lim.soft_max_mm + 1e-9, f"leg {leg} at {nut} mm"


@given(st.binary(min_size=1, max_size=300))
def test_random_bytes_are_answered_or_refused_as_a_stream(data):
    _, units = _drive()
    try:
        out, rest = answer_frames(units, data)
        fed("simulated drive: Modbus TCP frames")
    except FrameError:
        fed("simulated drive: Modbus TCP frames", refused=True)
        return
    assert len(rest) < len(data) or not out
