"""The simulated drive's own Modbus TCP server (drivers/sim/modbus_tcp.py) against pymodbus'
server in front of the same drive model, byte for byte, and against modbus-tk's client.

Two simulated drives with the same plant and a virtual clock at time scale 0 get the same raw
requests on two sockets; the replies must be equal, except where the Modbus specification and
pymodbus part ways (listed in `test_where_the_specification_and_pymodbus_differ`)."""

from __future__ import annotations

import socket
import struct
import threading

import pytest

from drivers.clock import VirtualClock
from drivers.modbus.profile import DriveProfile
from drivers.sim.drive_server import SimDriveServer
from drivers.plant.leg import LegPlant, default_leg_configs
from modbus_tk import defines as cst  # an independent client
from modbus_tk import modbus_tcp

pytestmark = pytest.mark.filterwarnings("ignore:isSet:DeprecationWarning")  # inside modbus-tk

PROFILE = DriveProfile.load(None)
REG = PROFILE.registers
UNIT = 1


class _Drive:
    """A simulated drive (leg 1) served by `engine`, with a raw socket to it."""

    def __init__(self, engine: str):
        plants = {1: LegPlant(default_leg_configs(0, 1)[0], seed=1)}
        self.server = SimDriveServer(plants, VirtualClock(0.0), PROFILE, lock=threading.RLock())
        self.port = self.server.start_tcp(engine=engine)
        self.sock = socket.create_connection(("127.0.0.1", self.port), timeout=2.0)
        self.tid = 0

    def ask(self, pdu: bytes, unit: int = UNIT, wait_s: float = 2.0) -> bytes | None:
        """The reply PDU to `pdu`, or None when nothing came within `wait_s`."""
        self.tid += 1
        self.sock.sendall(struct.pack(">HHHB", self.tid, 0, len(pdu) + 1, unit) + pdu)
        return self.reply(wait_s)

    def reply(self, wait_s: float = 2.0) -> bytes | None:
        self.sock.settimeout(wait_s)
        try:
            head = _recv_exactly(self.sock, 7)
        except socket.timeout:
            return None
        tid, pid, length, unit = struct.unpack(">HHHB", head)
        assert pid == 0
        return _recv_exactly(self.sock, length - 1)

    def close(self) -> None:
        self.sock.close()
        self.server.stop()


def _recv_exactly(sock: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = sock.recv(n - len(data))
        if not chunk:
            raise ConnectionError("closed")
        data += chunk
    return data


@pytest.fixture
def pair():
    ours, theirs = _Drive("station"), _Drive("pymodbus")
    yield ours, theirs
    ours.close()
    theirs.close()


def _read(fc: int, name: str, count: int | None = None) -> bytes:
    r = REG[name]
    return struct.pack(">BHH", fc, r.address, count or r.words)


def _enable_sequence() -> list[bytes]:
    cw = REG["controlword"].address
    return [struct.pack(">BHH", 6, cw, v) for v in (0x06, 0x07, 0x0F)]


def _move_23(target_mm: float) -> bytes:
    """Function 23 as the station sends it: controlword with new set-point + target, then the
    status run read back."""
    block = PROFILE.blocks["move_command"]
    words = [0] * block.words
    cw = REG["controlword"]
    words[cw.address - block.start] = 0x1F
    tr = REG["target_position"]
    words[tr.address - block.start : tr.end - block.start] = tr.encode(target_mm)
    st = PROFILE.blocks["status"]
    return struct.pack(f">BHHHHB{len(words)}H", 23, st.start, st.words, block.start, len(words), 2 * len(words), *words)


def test_served_functions_answer_byte_for_byte_like_pymodbus(pair):
    ours, theirs = pair
    sw = REG["statusword"].address
    requests = [
        _read(3, "statusword"), _read(4, "statusword"), _read(3, "vendor"), _read(3, "soft_limit_min"),
        struct.pack(">BHH", 3, 60000, 2),  # beyond the map: exception 02
        struct.pack(">BHH", 6, sw, 6),  # a read-only register: exception 02
        *_enable_sequence(),
        _move_23(12.345678), _read(3, "position_actual"), _move_23(-40.0),
        struct.pack(">BHHBH", 16, REG["controlword"].address, 1, 2, 0x0F),
        struct.pack(">BHHBH", 16, REG["controlword"].address, 1, 4, 0x0F),  # byte count != 2 x count: 03
        struct.pack(">BHHB2H", 16, REG["profile_velocity"].address, 2, 4, 0, 0),  # velocity 0: refused, 03
        bytes([0x2B, 0x0E, 4, 9]),  # an object the drive does not have: 02
        bytes([0x2B, 0x0D, 1, 0]),  # another MEI type: 01
    ]
    for pdu in requests:
        assert ours.ask(pdu) == theirs.ask(pdu), pdu.hex()
    # the same drive state after all that (position read through both)
    assert ours.ask(_read(3, "position_actual")) == theirs.ask(_read(3, "position_actual"))


def test_device_identification_differs_only_in_the_conformity_level(pair):
    ours, theirs = pair
    for pdu in (bytes([0x2B, 0x0E, 1, 0]), bytes([0x2B, 0x0E, 2, 0]), bytes([0x2B, 0x0E, 4, 1])):
        a, b = ours.ask(pdu), theirs.ask(pdu)
        # pymodbus claims 0x83 (extended objects); these drives hold the basic ones: 0x81
        assert a[3] == 0x81 and b[3] == 0x83
        assert a[:3] + a[4:] == b[:3] + b[4:]
    objects = ours.ask(bytes([0x2B, 0x0E, 1, 0]))
    assert objects[6] == 3 and b"StationSim" in objects


def test_no_drive_at_a_unit_id_means_no_reply(pair):
    ours, theirs = pair
    for drive in pair:
        assert drive.ask(_read(3, "statusword"), unit=9, wait_s=0.3) is None
        assert drive.ask(_read(3, "statusword")) is not None  # and the connection still serves
    # whatever the function (pymodbus answers its report-server-id for any unit)
    assert ours.ask(bytes([0x11]), unit=9, wait_s=0.3) is None
    ours.server.set_unresponsive(1)
    assert ours.ask(_read(3, "statusword"), wait_s=0.3) is None


def test_where_the_specification_and_pymodbus_differ(pair):
    """MODBUS Application Protocol v1.1b3: a quantity outside 1..125 is exception 03 (pymodbus
    fails to decode it and answers exception 01 for function 0); a function the drive does not
    serve is exception 01 (pymodbus' simulator answers coils, diagnostics, report server id and
    FIFO reads that no servo drive of ours has); a device-id read code outside 1..4 is 03."""
    ours, theirs = pair
    assert ours.ask(struct.pack(">BHH", 3, 0, 0)) == bytes([0x83, 0x03])
    assert ours.ask(struct.pack(">BHH", 3, 0, 126)) == bytes([0x83, 0x03])
    assert theirs.ask(struct.pack(">BHH", 3, 0, 126)) == bytes([0x80, 0x01])
    for fc in (1, 2, 5, 8):
        assert ours.ask(struct.pack(">BHH", fc, 0, 1)) == bytes([0x80 | fc, 0x01])
    assert ours.ask(bytes([0x11])) == bytes([0x91, 0x01])
    assert ours.ask(bytes([0x2B, 0x0E, 7, 0])) == bytes([0xAB, 0x03])
    assert ours.ask(struct.pack(">BHHHHB", 23, 0, 1, 0, 0, 0)) == bytes([0x97, 0x03])


def test_framing_split_joined_and_foreign_frames():
    drive = _Drive("station")
    try:
        sw = _read(3, "statusword")
        adu = lambda tid, pdu, pid=0: struct.pack(">HHHB", tid, pid, len(pdu) + 1, UNIT) + pdu  # noqa: E731
        # two requests in one segment: two replies, in order
        drive.sock.sendall(adu(41, sw) + adu(42, sw))
        raw = _recv_exactly(drive.sock, 2 * (7 + 4))
        assert struct.unpack_from(">H", raw, 0)[0] == 41 and struct.unpack_from(">H", raw, 11)[0] == 42
        # one request in three segments: answered once whole
        frame = adu(43, sw)
        for part in (frame[:3], frame[3:9], frame[9:]):
            drive.sock.sendall(part)
        assert drive.reply() is not None
        # a protocol id other than 0 is not Modbus: dropped, the next frame answered
        drive.sock.sendall(adu(44, sw, pid=7) + adu(45, sw))
        raw = _recv_exactly(drive.sock, 11)
        assert struct.unpack_from(">H", raw)[0] == 45
        # a length field no Modbus frame has: the drive closes the connection
        drive.sock.sendall(struct.pack(">HHHB", 46, 0, 300, UNIT) + b"\0" * 8)
        drive.sock.settimeout(2.0)
        assert drive.sock.recv(10) == b""
    finally:
        drive.close()


def test_modbus_tk_client_enables_moves_and_reads_back():
    drive = _Drive("station")
    master = modbus_tcp.TcpMaster("127.0.0.1", drive.port, timeout_in_sec=2.0)
    try:
        cw = REG["controlword"].address
        for value in (0x06, 0x07, 0x0F):
            master.execute(UNIT, cst.WRITE_SINGLE_REGISTER, cw, output_value=value)
        block = PROFILE.blocks["move_command"]
        words = [0] * block.words
        words[cw - block.start] = 0x1F
        tr = REG["target_position"]
        words[tr.address - block.start : tr.end - block.start] = list(struct.unpack(">2H", struct.pack(">i", 25_000_000)))
        pos = REG["position_actual"]
        got = master.execute(UNIT, cst.READ_WRITE_MULTIPLE_REGISTERS, pos.address, pos.words,
                             output_value=words, write_starting_address_fc23=block.start)
        assert struct.unpack(">i", struct.pack(">2H", *got))[0] == 25_000_000  # 25 mm in um counts
        (status,) = master.execute(UNIT, cst.READ_HOLDING_REGISTERS, REG["statusword"].address, 1)
        assert status & 0x0400  # target reached
        with pytest.raises(Exception, match="2"):  # modbus-tk raises ModbusError(2) for exception 02
            master.execute(UNIT, cst.WRITE_MULTIPLE_REGISTERS, REG["statusword"].address, output_value=[1])
    finally:
        master.close()
        drive.close()


def test_stop_closes_the_clients_connection_and_frees_the_port():
    drive = _Drive("station")
    assert drive.ask(_read(3, "statusword")) is not None  # accepted and served
    drive.server.stop()
    drive.sock.settimeout(2.0)
    assert drive.sock.recv(10) == b""
    with socket.socket() as s:  # a drive restarted on the same port can listen there again
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", drive.port))
        s.listen(1)
    drive.sock.close()
