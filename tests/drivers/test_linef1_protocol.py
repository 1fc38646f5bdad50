"""The µLine-F1 / HPI-3D protocol (docs/interferometer-protocol.md, "The µLine-F1 protocol"), checked
from its documented layout: every frame here is built byte by byte in the test, never with the
station's encoder, and played to the station's client over a real pseudo-terminal by a hand-made
instrument that checks the command bytes it receives and echoes them.

Layout (the public client l-pio/pylinef1): host -> device AA, 2-byte command, 4 zero bytes,
CRC; device -> host AA, 2-byte code, 12 data bytes, CRC; CRC-8 poly 0x31 init 0xFF, MSB first;
big-endian two's complement; distance bytes 0-6 in 100 pm; byte 9 bit 3 velocity overflow; byte
10 bit 0 laser stable, bit 3 signal good; byte 11 level; meteo: byte 0 sensor, 1-2 temperature
0.01 degC, 3 humidity %, 4 battery, 5 link, 6-7 pressure 10 Pa.
"""

from __future__ import annotations

import os
import queue
import select
import threading
import time
import tty

import pytest

from drivers.clock import VirtualClock
from drivers.errors import BeamBreak, CommTimeout, CountLost
from drivers.linef1 import protocol as lf
from drivers.linef1.client import LineF1Interferometer


def ref_crc(data: bytes) -> int:
    """CRC-8/NRSC-5 (poly 0x31, init 0xFF, no reflection, no final XOR), bit by bit."""
    crc = 0xFF
    for byte in data:
        for i in range(8):
            top = ((crc >> 7) ^ (byte >> (7 - i))) & 1
            crc = ((crc << 1) & 0xFF) ^ (0x31 if top else 0)
    return crc


def dev_frame(b1: int, b2: int, data: list[int]) -> bytes:
    assert len(data) == 12
    body = bytes([0xAA, b1, b2, *data])
    return body + bytes([ref_crc(body)])


def distance_data(counts_7_bytes: list[int], byte9: int = 0x00, byte10: int = 0x09, level: int = 0xC8) -> list[int]:
    return [*counts_7_bytes, 0x00, 0x00, byte9, byte10, level]


# the command frames as documented, with the CRC the catalogue's CRC-8/NRSC-5 gives
KNOWN_COMMANDS = {
    "distance on": bytes([0xAA, 0xB0, 0x32, 0, 0, 0, 0, 0x8E]),
    "set origin": bytes([0xAA, 0xB0, 0x48, 0, 0, 0, 0, 0x62]),
    "clear small signal": bytes([0xAA, 0xB0, 0x3D, 0, 0, 0, 0, 0xEB]),
    "clear overflow": bytes([0xAA, 0xB0, 0x3F, 0, 0, 0, 0, 0x7C]),
    "meteo on": bytes([0xAA, 0xB0, 0x79, 0, 0, 0, 0, 0x35]),
    "streams off": bytes([0xAA, 0xB0, 0x3C, 0, 0, 0, 0, 0x38]),
}


def test_crc8_is_the_catalogued_crc8_nrsc5_and_fits_the_known_frames():
    assert ref_crc(b"123456789") == 0xF7  # the catalogue's check value
    assert lf.crc8(b"123456789") == 0xF7
    for frame in KNOWN_COMMANDS.values():
        assert lf.crc8(frame[:7]) == frame[7] == ref_crc(frame[:7])
    assert lf.command_frame(b"\xB0\x32") == KNOWN_COMMANDS["distance on"]
    assert lf.command_frame(b"\xB0\x48") == KNOWN_COMMANDS["set origin"]
    ack = dev_frame(0xB0, 0x48, [0] * 12)
    assert lf.frame_ok(ack) and not lf.frame_ok(ack[:-1] + bytes([ack[-1] ^ 1]))


class HandInstrument:
    """The instrument's side of a pty, played by the test: reads 8-byte commands, records them,
    echoes each (unless told to stay silent for the next n), then sends what is queued for
    after that command, once the client's clock has moved on (a frame of the window it opened)."""

    def __init__(self, clock):
        self.clock = clock
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.port = os.ttyname(self.slave)
        self.received: list[bytes] = []
        self.after: dict[bytes, queue.Queue] = {}
        self.silent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def queue_after(self, command: bytes, frames: bytes, later: bool = True) -> None:
        """Send `frames` after the echo of `command`; `later`: once the client's clock moved on."""
        self.after.setdefault(command, queue.Queue()).put((frames, later))

    def send(self, data: bytes) -> None:
        os.write(self.master, data)

    def _run(self) -> None:
        buf = b""
        while not self._stop.is_set():
            if not select.select([self.master], [], [], 0.02)[0]:
                continue
            buf += os.read(self.master, 1024)
            while len(buf) >= 8:
                cmd, buf = buf[:8], buf[8:]
                self.received.append(cmd)
                if self.silent:
                    self.silent -= 1
                    continue
                echoed_at = self.clock.now()  # before the echo: the client moves its clock on once it has it
                os.write(self.master, dev_frame(cmd[1], cmd[2], [0] * 12))
                q = self.after.get(cmd)
                if q is not None and not q.empty():
                    frames, later = q.get()
                    deadline = time.monotonic() + 2.0
                    while later and self.clock.now() <= echoed_at and time.monotonic() < deadline:
                        time.sleep(0.001)
                    os.write(self.master, frames)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        os.close(self.master)
        os.close(self.slave)


AIR = dev_frame(0xB0, 0x0A, [0x00, 0x08, 0x59, 0x28, 0x5F, 0x63, 0x27, 0x94, 0, 0, 0, 0])  # 21.37 C, 40 %, 101320 Pa
MATERIAL_3 = dev_frame(0xB0, 0x0A, [0x03, 0xFF, 0x6A, 0x00, 0x50, 0x60, 0x00, 0x00, 0, 0, 0, 0])  # sensor 3: -1.50 C


@pytest.fixture(scope="module")
def rig():
    clock = VirtualClock(0.0)
    inst = HandInstrument(clock)
    # the meteo stream's first frames come with the echo of "meteo on"
    inst.queue_after(KNOWN_COMMANDS["meteo on"], AIR + MATERIAL_3, later=False)
    laser = LineF1Interferometer(inst.port, clock=clock, timeout_s=0.3, retries=1,
                                 index=lambda t, p, h: 1.0002)  # a round index: raw / 1.0002
    yield inst, laser, clock
    laser.close()
    inst.close()


def _read_with(inst, laser, frame: bytes):
    """One reading whose window holds the one `frame`, sent after the window's opening echo."""
    inst.queue_after(KNOWN_COMMANDS["clear small signal"], frame)
    return laser.read(3)


def test_start_up_and_zero_send_exactly_the_documented_commands_and_wait_for_their_echo(rig):
    inst, laser, _ = rig
    assert inst.received[:2] == [KNOWN_COMMANDS["distance on"], KNOWN_COMMANDS["meteo on"]]
    laser.zero(3)
    assert inst.received[2:5] == [KNOWN_COMMANDS["clear overflow"], KNOWN_COMMANDS["clear small signal"],
                                  KNOWN_COMMANDS["set origin"]]


def test_meteo_frames_decode_to_the_air_and_the_material_temperature_of_their_leg(rig):
    _, laser, _ = rig
    env = laser.environment()
    assert env.air_temp_c == pytest.approx(21.37)
    assert env.humidity_pct == 40.0
    assert env.air_pressure_hpa == pytest.approx(1013.20)
    assert env.material_temp_c[2] == pytest.approx(-1.50)  # negative: two's complement
    assert all(v != v for i, v in enumerate(env.material_temp_c) if i != 2)  # no other sensor: NaN


def test_distance_scaling_two_complement_and_the_station_s_air_index(rig):
    inst, laser, _ = rig
    laser.zero(3)
    # +12.3456789 mm = 123456789 counts of 100 pm = 0x00000007 5BCD15
    r = _read_with(inst, laser, dev_frame(0xB0, 0x15, distance_data([0, 0, 0, 0x07, 0x5B, 0xCD, 0x15])))
    assert r.position_mm == pytest.approx(12.3456789 / 1.0002, abs=1e-12)
    assert r.samples == 1 and r.frames_lost == 0 and r.beam_ok
    # -12.3456789 mm: 2^56 - 123456789 = 0xFFFFFFF8A432EB
    r = _read_with(inst, laser, dev_frame(0xB0, 0x15, distance_data([0xFF, 0xFF, 0xFF, 0xF8, 0xA4, 0x32, 0xEB])))
    assert r.position_mm == pytest.approx(-12.3456789 / 1.0002, abs=1e-12)
    # the extremes of 7 bytes: -2^55 counts = -3602879.70 mm; -1 count = -0.1 nm
    r = _read_with(inst, laser, dev_frame(0xB0, 0x15, distance_data([0x80, 0, 0, 0, 0, 0, 0])))
    assert r.position_mm == pytest.approx(-(2 ** 55) * 1e-7 / 1.0002, rel=1e-12)
    r = _read_with(inst, laser, dev_frame(0xB0, 0x15, distance_data([0xFF] * 7)))
    assert r.position_mm == pytest.approx(-1e-7 / 1.0002, abs=1e-15)
    # level byte: 0xC8 = 200 of 255
    assert r.signal_pct == pytest.approx(78.4)


def test_small_signal_and_unstable_laser_are_beam_breaks_and_overflow_loses_the_count(rig):
    inst, laser, _ = rig
    laser.zero(3)
    plus_1mm = [0, 0, 0, 0, 0x98, 0x96, 0x80]  # 10 000 000 counts
    with pytest.raises(BeamBreak, match="small signal"):
        _read_with(inst, laser, dev_frame(0xB0, 0x15, distance_data(plus_1mm, byte10=0x01, level=0x03)))
    with pytest.raises(BeamBreak, match="not stable"):
        _read_with(inst, laser, dev_frame(0xB0, 0x15, distance_data(plus_1mm, byte10=0x08)))
    r = _read_with(inst, laser, dev_frame(0xB0, 0x15, distance_data(plus_1mm)))
    assert r.position_mm == pytest.approx(1.0 / 1.0002)
    with pytest.raises(CountLost, match="overflow"):
        _read_with(inst, laser, dev_frame(0xB0, 0x15, distance_data(plus_1mm, byte9=0x08)))
    # lost until the origin is set again: refused without asking the instrument
    sent = len(inst.received)
    with pytest.raises(CountLost, match="until the origin is set again"):
        laser.read(3)
    assert len(inst.received) == sent
    laser.zero(3)
    assert _read_with(inst, laser, dev_frame(0xB0, 0x15, distance_data(plus_1mm))).position_mm == pytest.approx(1 / 1.0002)


def test_a_crc_error_and_a_cut_frame_are_dropped_and_the_next_frame_read(rig):
    inst, laser, _ = rig
    laser.zero(3)
    good = dev_frame(0xB0, 0x15, distance_data([0, 0, 0, 0, 0x98, 0x96, 0x80]))
    bad_crc = good[:-1] + bytes([good[-1] ^ 0x01])
    cut = dev_frame(0xB0, 0x15, distance_data([0, 0, 0, 0, 0, 0, 1]))[:9]
    before = laser.crc_errors
    r = _read_with(inst, laser, bad_crc + cut + good)
    assert r.position_mm == pytest.approx(1 / 1.0002)
    assert laser.crc_errors - before == 2  # one frame with a bad CRC, one cut short
    assert r.frames_lost == 2  # both in the window: the reading says so


def test_a_command_not_echoed_is_sent_again_then_reported(rig):
    inst, laser, _ = rig
    inst.silent = 1
    n = len(inst.received)
    laser.zero(3)  # its first command is not echoed the first time
    assert inst.received[n:n + 2] == [KNOWN_COMMANDS["clear overflow"]] * 2
    inst.silent = 2  # retries=1: two attempts, both unanswered
    t = time.monotonic()
    with pytest.raises(CommTimeout, match="clear the velocity-overflow flag.*not acknowledged in 2 attempt"):
        laser.zero(3)
    assert time.monotonic() - t < 2 * 0.3 + 0.5


def test_a_silent_stream_is_a_timeout_and_another_leg_is_refused(rig):
    inst, laser, _ = rig
    laser.zero(3)
    with pytest.raises(CommTimeout, match="no distance frame"):
        laser.read(3)
    with pytest.raises(Exception, match="one beam, zeroed on leg 3; leg 2 was not zeroed"):
        laser.read(2)
    assert "no identity query" in laser.identity()


def test_a_velocity_frame_decodes_in_100_nm_per_s_with_the_same_flags():
    # -1.5 mm/s = -15000 counts of 100 nm/s = 0xFFFFC568; overflow, small signal, level 7
    frame = dev_frame(0xB0, 0x16, [0xFF, 0xFF, 0xC5, 0x68, 0, 0, 0, 0, 0, 0x08, 0x01, 0x07])
    assert lf.frame_ok(frame)
    v = lf.decode_velocity(frame[3:15])
    assert v.velocity_m_s == pytest.approx(-1.5e-3) and v.distance_m is None
    assert v.overflow and v.laser_stable and not v.signal_good and v.level == 7
    m = lf.decode_meteo(MATERIAL_3[3:15])
    assert (m.sensor_id, m.temp_c, m.humidity_pct, m.battery, m.link, m.pressure_pa) == (3, -1.5, 0.0, 0x50, 0x60, 0.0)
