"""The station's Modbus client against independent implementations: a modbus-tk server holding
the documented register map (values packed here with struct, not with our codec), and mbpoll
(libmodbus) reading the simulated drive."""

from __future__ import annotations

import os
import shutil
import socket
import struct
import subprocess
import threading

import pytest

from drivers.errors import TableError
from drivers.interfaces import TableBank
from drivers.modbus.client import ModbusBus, ModbusServoAxis

from modbus_tk import defines as cst  # the independent peer: a test dependency, never skipped
from modbus_tk import modbus_tcp
from tests.tooling import require_tool

UNIT = 3
pytestmark = pytest.mark.filterwarnings("ignore:isSet:DeprecationWarning")  # inside modbus-tk



def _crc_modbus(data: bytes) -> int:
    """Reference CRC-16/MODBUS (reflected poly 0x8005), written independently of the codec."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            lsb = crc & 1
            crc >>= 1
            if lsb:
                crc ^= 0xA001
    return crc


def _regs(fmt: str, *values) -> list[int]:
    """Big-endian struct packing split into 16-bit registers (high word first for 32 bits)."""
    data = struct.pack(">" + fmt, *values)
    return list(struct.unpack(f">{len(data) // 2}H", data))


def _ascii(text: str, words: int) -> list[int]:
    return _regs(f"{2 * words}s", text.encode("ascii").ljust(2 * words, b"\0"))


class _TkServer(modbus_tcp.TcpServer):
    """modbus-tk TCP server that says when it listens."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.ready = threading.Event()

    def _do_init(self):
        super()._do_init()
        self.ready.set()


@pytest.fixture
def tk_drive(profile):
    server = _TkServer(port=0, address="127.0.0.1")
    server.start()
    try:
        assert server.ready.wait(5), "modbus-tk server did not start"
        port = server._sock.getsockname()[1]
        slave = server.add_slave(UNIT)
        slave.add_block("map", cst.HOLDING_REGISTERS, 0, profile.table.bank_end(1) + 10)
        bus = ModbusBus.from_url(f"tcp://127.0.0.1:{port}", timeout_s=1.0)
        yield slave, bus
        bus.close()
    finally:
        # modbus-tk polls with a 1 s select; a connection wakes it so stop() returns at once
        server._go.clear()
        if server.ready.is_set():
            try:
                socket.create_connection(server._sock.getsockname()[:2], timeout=1).close()
            except OSError:
                pass  # it had already woken up and closed its socket
        server.stop()


def test_client_reads_an_independent_server(tk_drive, profile):
    slave, bus = tk_drive
    a = profile.address
    slave.set_values("map", a("vendor"), _ascii("ACME Drives", 8))
    slave.set_values("map", a("product"), _ascii("LX-402", 8))
    slave.set_values("map", a("serial"), _ascii("AB123456", 8))
    slave.set_values("map", a("firmware"), _ascii("2.7.1", 4))
    slave.set_values("map", a("map_version"), [profile.map_version])
    slave.set_values("map", a("soft_limit_min"), _regs("ii", -80_000_000, 85_500_000))
    slave.set_values("map", a("max_velocity"), _regs("IIII", 15_000, 120_000, 5_000, 50_000))
    # CiA 402 "operation enabled" (0x27) + remote (bit 9) + target reached (bit 10)
    slave.set_values("map", a("statusword"), [0x0627])
    slave.set_values("map", a("position_actual"), _regs("iiHiHH", -12_345_678, 750, 0, 12_345, 1, 1))
    # a table in bank 1: 5 points from -10 mm every 2.5 mm, entries in 0.01 um
    fwd = [120, -35, 0, 7, -32768 + 1]
    rev = [-5, 4, 300, -300, 1]
    entries = _regs("5h5h", *fwd, *rev)
    base = profile.table.bank_base[1]
    slave.set_values("map", base + profile.table.fwd_offset, _regs("5h", *fwd))
    slave.set_values("map", base + profile.table.rev_offset, _regs("5h", *rev))
    crc = _crc_modbus(struct.pack(f">{len(entries)}H", *entries))
    slave.set_values("map", base, [5] + _regs("iI", -10_000_000, 2_500_000) + [profile.table.units_code, crc, 1])

    ax = ModbusServoAxis(bus, UNIT, profile)
    assert ax.identity() == "ACME Drives LX-402 s/n AB123456 fw 2.7.1"
    ax.check_map_version()
    lim = ax.limits()
    assert (lim.min_mm, lim.max_mm, lim.max_velocity_mm_s, lim.max_accel_mm_s2) == pytest.approx((-80.0, 85.5, 15.0, 120.0))
    st = ax.status()
    assert st.state == "operation_enabled" and st.target_reached and not st.fault
    assert st.position_mm == pytest.approx(-12.345678, abs=1e-9)
    assert st.following_error_um == pytest.approx(0.75)
    assert st.load_n == pytest.approx(123.45)
    assert st.active_bank == 1 and st.table_enabled
    tb = ax.read_table(1)
    assert (tb.start_mm, tb.spacing_mm, tb.checksum) == (pytest.approx(-10.0), pytest.approx(2.5), crc)
    assert tb.error_fwd_um == pytest.approx([v * 0.01 for v in fwd])
    assert tb.error_rev_um == pytest.approx([v * 0.01 for v in rev])
    # a soft limit from the drive's own registers (-80 mm here, not the profile's default)
    with pytest.raises(Exception, match="soft limits -80.000"):
        ax.move_to(-80.5)


def test_client_writes_what_the_map_documents(tk_drive, profile):
    slave, bus = tk_drive
    a = profile.address
    slave.set_values("map", a("soft_limit_min"), _regs("iiIIII", -95_000_000, 95_000_000, 20_000, 200_000, 10_000, 100_000))
    slave.set_values("map", a("statusword"), [0x0627])
    ax = ModbusServoAxis(bus, UNIT, profile)
    ax.limits()  # read once per axis
    tx = bus.transactions
    ax.move_to(25.5)
    # the default profile serves function 23, which modbus-tk's server implements too: the
    # move's write and the status read in one transaction
    assert bus.transactions - tx == 1, "one read/write (function 23)"
    assert bus.wire.transactions == bus.transactions
    # controlword: enable operation (0x0F) + new set-point (bit 4); target int32 nm, high word first
    assert list(slave.get_values("map", a("controlword"), 3)) == [0x001F] + _regs("i", 25_500_000)

    table = TableBank(-1.0, 0.5, (1.25, -2.5, 0.0), (0.01, 299.99, -300.0))
    with pytest.raises(TableError, match="does not accept bank 1 as valid"):
        ax.write_table(1, table)  # modbus-tk is no drive: nothing computes the valid flag
    t = profile.table
    fwd = _regs("3h", 125, -250, 0)
    rev = _regs("3h", 1, 29999, -30000)
    assert list(slave.get_values("map", t.fwd_address(1), 3)) == fwd
    assert list(slave.get_values("map", t.rev_address(1), 3)) == rev
    crc = _crc_modbus(struct.pack(">6H", *fwd, *rev))
    header = list(slave.get_values("map", t.bank_base[1], 7))
    assert header == [3] + _regs("iI", -1_000_000, 500_000) + [t.units_code, crc]
    ax.activate_table(1)
    assert slave.get_values("map", a("active_bank"), 1)[0] == 1


def test_mbpoll_reads_leg3_position_actual_like_the_station(sim_drives):
    mbpoll = require_tool("mbpoll")
    sd = sim_drives()
    ax = sd.axis(3)
    ax.enable()
    ax.move_to(-37.654321)
    port = sd.url.rsplit(":", 1)[1]
    addr = sd.profile.address("position_actual")
    out = subprocess.run(
        [mbpoll, "-m", "tcp", "-p", port, "-a", "3", "-r", str(addr), "-t", "4:int", "-B", "-c", "1", "-1", "-0", "127.0.0.1"],
        capture_output=True, text=True, timeout=10,
    )
    assert out.returncode == 0, out.stderr
    line = next(ln for ln in out.stdout.splitlines() if ln.startswith(f"[{addr}]:"))
    counts = int(line.split(":", 1)[1])
    assert counts * sd.profile.registers["position_actual"].scale == pytest.approx(ax.status().position_mm, abs=1e-12)
    assert counts == -37_654_321


def test_mbpoll_reads_over_rtu_on_the_pty(sim_drives):
    mbpoll = require_tool("mbpoll")
    sd = sim_drives(rtu=True)
    ax = sd.axis(3)
    ax.enable()
    ax.move_to(12.5)
    path = sd.url.removeprefix("rtu://").split("?")[0]
    ax.close()
    for b in sd.buses:
        b.close()  # mbpoll wants the port for itself
    addr = sd.profile.address("position_actual")
    out = subprocess.run(
        [mbpoll, "-m", "rtu", "-b", "115200", "-P", "none", "-a", "3", "-r", str(addr), "-t", "4:int", "-B", "-c", "1",
         "-1", "-0", path],
        capture_output=True, text=True, timeout=10,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    line = next(ln for ln in out.stdout.splitlines() if ln.startswith(f"[{addr}]:"))
    assert int(line.split(":", 1)[1]) == 12_500_000
