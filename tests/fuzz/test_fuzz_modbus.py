"""Fuzzing the Modbus client (drivers/modbus/client.py) with a server on 127.0.0.1 that answers
garbage: random bytes, short frames, wrong function codes, transaction and unit ids, exception
replies, bad byte counts and lengths, silence, late replies, closed connections, trailing junk
(tests/fuzz/modbus_fuzz_server.py).

Property: every call returns what the drive really sent (register values of a correct reply),
or raises a DriverError (CommTimeout, RequestRefused, ...); never another exception or a hang.
And the link recovers: the next request after any of it gets its own correct reply.
"""

from __future__ import annotations

import pytest
from hypothesis import example, given, settings, strategies as st

from drivers.errors import DriverError
from drivers.interfaces import DriveStatus
from drivers.modbus.client import ModbusBus, ModbusServoAxis
from drivers.modbus.profile import DriveProfile
from tests.fuzz.budget import INPUTS, examples, fed
from tests.fuzz.modbus_fuzz_server import REPLIES, FuzzModbusServer

TIMEOUT_S = 0.2  # per request, both attempts; the server's late replies come after 0.3 s


@pytest.fixture(scope="module")
def server():
    srv = FuzzModbusServer(late_s=0.3)
    yield srv
    srv.stop()
    INPUTS["Modbus fuzz server: requests answered"] += srv.requests
    INPUTS["Modbus fuzz server: of them not correctly"] += srv.requests - srv.replies.get("valid", 0)


@pytest.fixture(scope="module")
def profile():
    return DriveProfile.load()


ops = st.lists(st.one_of(
    st.tuples(st.just("read"), st.integers(0, 200), st.integers(1, 12)),
    st.tuples(st.just("write"), st.integers(0, 200), st.lists(st.integers(0, 0xFFFF), min_size=1, max_size=5)),
    st.tuples(st.just("status"), st.just(0), st.just(0)),
    st.tuples(st.just("identity"), st.just(0), st.just(0)),
), min_size=1, max_size=3)
# mostly garbage, few waits (silence / late cost a timeout each)
reply = st.one_of(st.sampled_from([r for r in REPLIES if r not in ("silence", "late")]), st.sampled_from(REPLIES))


@settings(max_examples=examples(60), deadline=10000)
@given(st.lists(reply, min_size=1, max_size=6), ops, st.integers(0, 2**16))
@example(["wrong_tid"], [("read", 10, 2)], 1)
@example(["wrong_unit"], [("read", 10, 2)], 2)
@example(["late", "valid"], [("read", 10, 2), ("read", 20, 3)], 3)
@example(["extra", "valid"], [("read", 10, 2), ("read", 20, 3)], 4)
@example(["bad_count"], [("read", 10, 4)], 5)
@example(["wrong_function", "wrong_function"], [("read", 3, 1), ("read", 3, 1)], 1)  # found: accepted as the answer
@example(["bad_length", "wrong_function", "garbled", "late"], [("write", 127, [0]), ("write", 127, [0])], 9952)
@example(["valid", "extra", "late", "wrong_unit", "bad_length", "late"], [("identity", 0, 0), ("identity", 0, 0)], 1934)
def test_client_against_garbage(server, profile, plan, operations, seed):
    server.reset(plan, seed)
    bus = ModbusBus.tcp("127.0.0.1", server.port, timeout_s=TIMEOUT_S, retries=1)
    axis = ModbusServoAxis(bus, 1, profile)
    try:
        for op, address, arg in operations:
            try:
                if op == "read":
                    regs = bus.read(1, address, arg)
                    assert len(regs) == arg and all(0 <= r <= 0xFFFF for r in regs)
                    assert regs in server.valid_sent, f"read returned {regs}, which the drive did not send"
                elif op == "write":
                    assert bus.write(1, address, arg) is None
                elif op == "status":
                    assert isinstance(axis.status(), DriveStatus)
                else:
                    assert isinstance(axis.identity(), str)
            except DriverError as exc:
                fed("Modbus reply (client call)", refused=True)
                assert "127.0.0.1" in str(exc), exc
            else:
                fed("Modbus reply (client call)")
        # the link recovers: with the plan used up, a read gets its own correct reply
        server.plan.clear()
        server.wait_idle()  # the server is not holding back a late reply (it would delay this one)
        sent_before = len(server.valid_sent)
        regs = bus.read(1, 7, 3)
        # (a retry may be answered twice, both replies to this read: either is its answer)
        assert regs in server.valid_sent[sent_before:], f"after {plan} the next read returned {regs}, not a reply to it"
    finally:
        axis.close()
        bus.close()
