"""The µLine-F1 / HPI-3D serial protocol (Lasertex, sold by Status Pro): frames, CRC, scaling.

Both sides use this module: the station's client (drivers/linef1/client.py) and the simulated
instrument (drivers/sim/linef1_server.py). The layout is as the unofficial public client
github l-pio/pylinef1 uses it (not the vendor's manual); docs/interferometer-protocol.md,
"The µLine-F1 protocol", states it in full and says what is not publicly described.

- Host -> device: 8 bytes = START, a 2-byte command, 4 data bytes (zeros for every command), CRC.
- Device -> host: 16 bytes = START, a 2-byte command, 12 data bytes, CRC. A command is
  acknowledged by a frame carrying the same command code; data frames carry DISTANCE, VELOCITY
  or METEO.
- CRC-8, polynomial 0x31, initial 0xFF, no reflection, no final XOR, over every byte before it.
- Integers big-endian two's complement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

BAUDRATE = 3_000_000  # a USB virtual COM port; 8N1, no flow control
START = 0xAA
COMMAND_BYTES = 8
FRAME_BYTES = 16
DATA_BYTES = 12

CRC_POLY = 0x31
CRC_INIT = 0xFF

# commands to the device (data bytes all zero)
CMD_DISTANCE_ON = b"\xB0\x32"
CMD_DISTANCE_OFF = b"\xB0\x33"
CMD_VELOCITY_ON = b"\xB0\x34"
CMD_VELOCITY_OFF = b"\xB0\x35"
CMD_STREAMS_OFF = b"\xB0\x3C"
CMD_CLEAR_SMALL_SIGNAL = b"\xB0\x3D"
CMD_CLEAR_OVERFLOW = b"\xB0\x3F"
CMD_CLEAR_CAPTURE = b"\xB0\x40"
CMD_SET_ORIGIN = b"\xB0\x48"  # "clear the measurement": the distance reads 0 here from now on
CMD_METEO_ON = b"\xB0\x79"
CMD_METEO_OFF = b"\xB0\x7A"
COMMANDS = {
    CMD_DISTANCE_ON: "distance stream on", CMD_DISTANCE_OFF: "distance stream off",
    CMD_VELOCITY_ON: "velocity stream on", CMD_VELOCITY_OFF: "velocity stream off",
    CMD_STREAMS_OFF: "every stream off", CMD_CLEAR_SMALL_SIGNAL: "clear the small-signal flag",
    CMD_CLEAR_OVERFLOW: "clear the velocity-overflow flag", CMD_CLEAR_CAPTURE: "clear the external-capture flag",
    CMD_SET_ORIGIN: "set the origin", CMD_METEO_ON: "meteo stream on", CMD_METEO_OFF: "meteo stream off",
}

# data frames from the device
FRAME_DISTANCE = b"\xB0\x15"
FRAME_VELOCITY = b"\xB0\x16"
FRAME_METEO = b"\xB0\x0A"
DATA_FRAMES = (FRAME_DISTANCE, FRAME_VELOCITY, FRAME_METEO)

# scaling (data bytes, 0-based within the 12 data bytes)
DISTANCE_M_PER_COUNT = 1e-10  # bytes 0-6: 100 pm
VELOCITY_M_S_PER_COUNT = 1e-7  # bytes 0-3: 100 nm/s
TEMP_C_PER_COUNT = 0.01  # meteo bytes 1-2
PRESSURE_PA_PER_COUNT = 10.0  # meteo bytes 6-7
FLAG_BYTE_OVERFLOW, FLAG_BIT_OVERFLOW = 9, 3  # velocity overflow: the count is lost
FLAG_BYTE_STATE, FLAG_BIT_LASER_STABLE = 10, 0
FLAG_BIT_SIGNAL_GOOD = 3  # in byte 10: clear = small signal (a broken beam)
LEVEL_BYTE = 11  # signal level, unit not stated

STREAM_RATE_HZ = 25.0  # distance or velocity frames, "about" (the public client's comment)
METEO_RATE_HZ = 1.0  # per sensor
AIR_SENSOR_ID = 0  # meteo sensor 0 = the air sensor; 1, 2, ... = material sensors

DISTANCE_BYTES = 7
_DISTANCE_LIMIT = 1 << (8 * DISTANCE_BYTES - 1)


class LineF1Error(ValueError):
    """A frame that does not fit the layout (wrong length, start byte, CRC, value out of range)."""


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ CRC_POLY) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


_CRC_TABLE = _crc_table()  # a byte at a time: 25 frames a second on both sides of the line


def crc8(data: bytes) -> int:
    """CRC-8: polynomial 0x31, initial 0xFF, MSB first, no reflection, no final XOR."""
    crc = CRC_INIT
    for byte in data:
        crc = _CRC_TABLE[crc ^ byte]
    return crc


def signed(data: bytes) -> int:
    """Big-endian two's complement."""
    return int.from_bytes(data, "big", signed=True)


def command_frame(code: bytes) -> bytes:
    """The 8 bytes that send command `code` (2 bytes) with zero data."""
    if len(code) != 2:
        raise LineF1Error(f"a command code is 2 bytes, got {code!r}")
    body = bytes([START]) + code + bytes(4)
    return body + bytes([crc8(body)])


def check_command(frame: bytes) -> bytes:
    """The command code of an 8-byte host frame (LineF1Error if malformed)."""
    if len(frame) != COMMAND_BYTES or frame[0] != START:
        raise LineF1Error(f"a command frame is {COMMAND_BYTES} bytes starting 0xAA, got {frame.hex(' ')}")
    if crc8(frame[:-1]) != frame[-1]:
        raise LineF1Error(f"command frame CRC 0x{frame[-1]:02X}, computed 0x{crc8(frame[:-1]):02X}")
    return bytes(frame[1:3])


def device_frame(code: bytes, data: bytes) -> bytes:
    """A 16-byte device frame: START, `code`, 12 data bytes, CRC."""
    if len(code) != 2 or len(data) != DATA_BYTES:
        raise LineF1Error(f"a device frame holds a 2-byte code and {DATA_BYTES} data bytes")
    body = bytes([START]) + code + data
    return body + bytes([crc8(body)])


def ack_frame(code: bytes) -> bytes:
    """The acknowledgement of command `code`: a frame carrying the same code (data zeros: the
    public client does not read them)."""
    return device_frame(code, bytes(DATA_BYTES))


def frame_ok(frame: bytes) -> bool:
    """True for 16 bytes that start with 0xAA and carry a matching CRC."""
    return len(frame) == FRAME_BYTES and frame[0] == START and crc8(frame[:-1]) == frame[-1]


@dataclass(frozen=True)
class DistanceFrame:
    """A distance (or velocity) frame. `distance_m`: raw optical distance from the origin,
    metres, positive = away from the origin as the instrument counts it, NOT compensated for the
    air (the software's job). `velocity_m_s` is set instead for a velocity frame.
    `overflow`: velocity overflow (lost count: not valid until the origin is set again);
    `laser_stable`; `signal_good` (False = small signal, e.g. a broken beam); `level` 0..255."""

    distance_m: float | None
    velocity_m_s: float | None
    overflow: bool
    laser_stable: bool
    signal_good: bool
    level: int


@dataclass(frozen=True)
class MeteoFrame:
    """One environment sensor: `sensor_id` 0 = air, 1.. = material; temperature degC (0.01),
    humidity %RH (1), battery and link (units not stated), pressure Pa (10 Pa; air sensor)."""

    sensor_id: int
    temp_c: float
    humidity_pct: float
    battery: int
    link: int
    pressure_pa: float


def _flags(data: bytes) -> tuple[bool, bool, bool, int]:
    state = data[FLAG_BYTE_STATE]
    return (bool(data[FLAG_BYTE_OVERFLOW] >> FLAG_BIT_OVERFLOW & 1), bool(state >> FLAG_BIT_LASER_STABLE & 1),
            bool(state >> FLAG_BIT_SIGNAL_GOOD & 1), data[LEVEL_BYTE])


def decode_distance(data: bytes) -> DistanceFrame:
    overflow, stable, good, level = _flags(data)
    return DistanceFrame(signed(data[:DISTANCE_BYTES]) * DISTANCE_M_PER_COUNT, None, overflow, stable, good, level)


def decode_velocity(data: bytes) -> DistanceFrame:
    overflow, stable, good, level = _flags(data)
    return DistanceFrame(None, signed(data[:4]) * VELOCITY_M_S_PER_COUNT, overflow, stable, good, level)


def decode_meteo(data: bytes) -> MeteoFrame:
    return MeteoFrame(sensor_id=signed(data[0:1]), temp_c=signed(data[1:3]) * TEMP_C_PER_COUNT,
                      humidity_pct=float(signed(data[3:4])), battery=data[4], link=data[5],
                      pressure_pa=signed(data[6:8]) * PRESSURE_PA_PER_COUNT)


def _flag_bytes(overflow: bool, laser_stable: bool, signal_good: bool, level: int) -> bytes:
    return bytes([(1 << FLAG_BIT_OVERFLOW) if overflow else 0,
                  ((1 << FLAG_BIT_LASER_STABLE) if laser_stable else 0) | ((1 << FLAG_BIT_SIGNAL_GOOD) if signal_good else 0),
                  max(0, min(255, int(level)))])


def distance_frame(distance_m: float, *, overflow: bool = False, laser_stable: bool = True,
                   signal_good: bool = True, level: int = 200) -> bytes:
    """A distance frame (the simulated instrument's side). `distance_m` rounded to 100 pm."""
    counts = round(distance_m / DISTANCE_M_PER_COUNT)
    if not -_DISTANCE_LIMIT <= counts < _DISTANCE_LIMIT:
        raise LineF1Error(f"distance {distance_m} m does not fit {DISTANCE_BYTES} bytes of 100 pm")
    data = counts.to_bytes(DISTANCE_BYTES, "big", signed=True) + bytes(2) + _flag_bytes(overflow, laser_stable, signal_good, level)
    return device_frame(FRAME_DISTANCE, data)


def meteo_frame(sensor_id: int, temp_c: float, humidity_pct: float = 0.0, pressure_pa: float = 0.0,
                battery: int = 100, link: int = 100) -> bytes:
    """A meteo frame (the simulated instrument's side), values rounded to the frame's units."""
    if not all(math.isfinite(v) for v in (temp_c, humidity_pct, pressure_pa)):
        raise LineF1Error("meteo values must be finite")
    data = (int(sensor_id).to_bytes(1, "big", signed=True) + round(temp_c / TEMP_C_PER_COUNT).to_bytes(2, "big", signed=True)
            + round(humidity_pct).to_bytes(1, "big", signed=True) + bytes([battery & 0xFF, link & 0xFF])
            + round(pressure_pa / PRESSURE_PA_PER_COUNT).to_bytes(2, "big", signed=True) + bytes(4))
    return device_frame(FRAME_METEO, data)
