"""Function 23 (read/write multiple registers) for a move, where the drive profile says the
drive serves it: the real client against the real simulated drive over Modbus TCP and RTU on a
pty, an independent client (modbus-tk) against the simulated drive, the simulated drive's
refusal (exception 01) under a profile without it, and the RTU wire tally. mbpoll cannot send
function 23 (it reads and writes only), so it is not used here."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest
from modbus_tk import defines as cst
from modbus_tk import modbus_tcp
from modbus_tk.exceptions import ModbusError

from drivers.clock import VirtualClock
from drivers.modbus.client import ModbusBus, ModbusServoAxis, RequestRefused
from drivers.modbus.profile import DEFAULT_PROFILE, DriveProfile, ProfileError
from drivers.modbus.wire import WireTally, rtu_frame_bytes, rtu_ms
from drivers.sim.drive_server import SimDriveServer
from drivers.plant.leg import LegPlant, default_leg_configs

pytestmark = pytest.mark.filterwarnings("ignore:isSet:DeprecationWarning")  # inside modbus-tk


def _profile_without_fc23(tmp_path: Path) -> DriveProfile:
    text = DEFAULT_PROFILE.read_text(encoding="utf-8")
    assert "read_write_multiple = true" in text
    p = tmp_path / "no_fc23.toml"
    p.write_text(text.replace("read_write_multiple = true", "read_write_multiple = false"), encoding="utf-8")
    return DriveProfile.load(p)


def _serve(profile: DriveProfile, rtu: bool = False):
    plants = {1: LegPlant(default_leg_configs(0, 1)[0], seed=1)}
    server = SimDriveServer(plants, VirtualClock(0.0), profile, lock=threading.RLock())
    url = f"rtu://{server.start_rtu()}?baud=115200" if rtu else f"tcp://127.0.0.1:{server.start_tcp()}"
    return server, url


def _moves(profile: DriveProfile, url: str, targets) -> tuple[int, WireTally, list[float]]:
    bus = ModbusBus.from_url(url, timeout_s=2.0)
    ax = ModbusServoAxis(bus, 1, profile)
    try:
        ax.enable()
        ax.move_to(0.0)
        tx, wire = bus.transactions, bus.wire.copy()
        got = [ax.move_to(t).position_mm for t in targets]
        return bus.transactions - tx, bus.wire - wire, got
    finally:
        ax.close()


@pytest.mark.parametrize("rtu", [False, True], ids=["tcp", "rtu-pty"])
def test_a_move_is_one_function_23_transaction_where_the_profile_allows_it(tmp_path, rtu):
    targets = (1.0, -2.5, 7.125, -40.0)
    results = {}
    for name, prof in (("fc23", DriveProfile.load()), ("plain", _profile_without_fc23(tmp_path))):
        server, url = _serve(prof, rtu)
        try:
            results[name] = _moves(prof, url, targets)
            stats = server.frame_stats()
        finally:
            server.stop()
        assert stats.gap_violations == 0 and stats.oversize == 0
        assert stats.read_write_requests == (len(targets) + 1 if name == "fc23" else 0)  # + the move to 0
    (tx23, wire23, pos23), (tx, wire, pos) = results["fc23"], results["plain"]
    assert pos23 == pytest.approx(list(targets), abs=1e-6) and pos == pytest.approx(pos23, abs=1e-12)
    assert (tx23, tx) == (len(targets), 2 * len(targets))
    assert wire23.transactions == tx23 and wire.transactions == tx
    # fewer bytes too: one request header and one reply instead of two of each
    assert wire23.bytes < wire.bytes
    assert rtu_ms(wire23, 115200) < 0.75 * rtu_ms(wire, 115200)


def test_a_drive_without_function_23_refuses_it_with_exception_01(tmp_path):
    prof = _profile_without_fc23(tmp_path)
    server, url = _serve(prof)
    bus = ModbusBus.from_url(url, timeout_s=2.0)
    try:
        sw = prof.address("statusword")
        with pytest.raises(RequestRefused, match="Modbus exception 1 \\(illegal function\\)") as exc:
            bus.write_read(1, prof.address("controlword"), [0x06], sw, 1)
        assert exc.value.exception_code == 1
        assert server.frame_stats().refused_functions == 1
        assert bus.read(1, sw, 1)  # the line is fine afterwards
        # the client never sends it under that profile: a move is a write and a read
        ax = ModbusServoAxis(bus, 1, prof)
        ax.enable()
        ax.limits()  # read once per axis
        tx = bus.transactions
        ax.move_to(3.0)
        assert bus.transactions - tx == 2 and server.frame_stats().refused_functions == 1
        ax.close()
    finally:
        bus.close()
        server.stop()


def test_modbus_tk_speaks_function_23_to_the_simulated_drive():
    prof = DriveProfile.load()
    server, url = _serve(prof)
    master = modbus_tcp.TcpMaster("127.0.0.1", int(url.rsplit(":", 1)[1]), timeout_in_sec=2.0)
    try:
        cw, sw = prof.address("controlword"), prof.address("statusword")
        # CiA 402 shutdown -> switch on -> enable operation, each written with function 23 and
        # the statusword read back in the same transaction (the write comes first)
        for cmd, state in ((0x06, 0x21), (0x07, 0x23), (0x0F, 0x27)):
            (status,) = master.execute(1, cst.READ_WRITE_MULTIPLE_REGISTERS, sw, 1, output_value=[cmd],
                                       write_starting_address_fc23=cw)
            assert status & 0x6F == state, f"controlword 0x{cmd:02X}: statusword 0x{status:04X}"
        assert server.frame_stats().read_write_requests == 3
    finally:
        master.close()
        server.stop()


def test_modbus_tk_gets_exception_01_where_the_profile_has_no_function_23(tmp_path):
    prof = _profile_without_fc23(tmp_path)
    server, url = _serve(prof)
    master = modbus_tcp.TcpMaster("127.0.0.1", int(url.rsplit(":", 1)[1]), timeout_in_sec=2.0)
    try:
        with pytest.raises(ModbusError) as exc:
            master.execute(1, cst.READ_WRITE_MULTIPLE_REGISTERS, prof.address("statusword"), 1, output_value=[0x06],
                           write_starting_address_fc23=prof.address("controlword"))
        assert exc.value.get_exception_code() == 1
    finally:
        master.close()
        server.stop()


def test_rtu_frame_sizes_and_wire_time():
    # read 2 registers: 01 03 00 10 00 02 CRC (8) -> 01 03 04 xx xx xx xx CRC (9)
    assert rtu_frame_bytes(3, read_words=2) == (8, 9)
    # write 3 registers: 01 10 00 10 00 03 06 + 6 data + CRC (15) -> 01 10 00 10 00 03 CRC (8)
    assert rtu_frame_bytes(16, write_words=3) == (15, 8)
    # function 23, write 3 and read 2: 01 17 r r n n w w m m 06 + 6 data + CRC (19) -> 9
    assert rtu_frame_bytes(23, read_words=2, write_words=3) == (19, 9)
    t = WireTally()
    t.add(3, read_words=2)
    # 17 bytes of 11 bits at 9600 baud + 2 x 3.5 characters of silence + a 10 ms gap
    assert rtu_ms(t, 9600, gap_ms=10.0) == pytest.approx((17 + 7) * 11 / 9600 * 1000 + 10.0)


def test_profile_key_must_be_a_boolean(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(DEFAULT_PROFILE.read_text(encoding="utf-8").replace("read_write_multiple = true", "read_write_multiple = 1"),
                 encoding="utf-8")
    with pytest.raises(ProfileError, match="read_write_multiple: must be true or false"):
        DriveProfile.load(p)


def test_shipped_real_profiles_leave_function_23_off():
    for name in ("kinco_fd.toml", "delta_asda_a2.toml"):
        assert DriveProfile.load(DEFAULT_PROFILE.parent / name).protocol.read_write_multiple is False
    assert DriveProfile.load().protocol.read_write_multiple is True
