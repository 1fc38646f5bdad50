"""The interferometer's serial line protocol: framing, checksum, commands and reply parsing.

Shared by the client (drivers.interferometer.client) and the simulated instrument
(drivers.sim.interferometer_server) so both sides agree byte for byte. The full description, with
an example exchange, timing and error codes, is docs/interferometer-protocol.md.

Summary: ASCII, 8N1, 115200 baud by default. A command is one line ending in "\\n" (a "\\r\\n"
is accepted). Every reply is one line ``<field>,<field>,...*HH\\r\\n`` where HH is the NMEA-style
checksum: the XOR of all bytes before '*', as two uppercase hex digits.

Parsing functions raise `ProtocolError` (a ValueError) naming what is wrong; the client turns it
into `drivers.errors.FramingError` once its retries are used up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from drivers.errors import DriverError

TERMINATOR = b"\r\n"
COMMAND_TERMINATOR = b"\n"
MAX_LINE_BYTES = 256  # longer lines are noise: the longest legal reply is under 160 bytes
DEFAULT_BAUDRATE = 115200
MAX_AVERAGING_S = 10.0
STATUSES = ("OK", "BEAM", "LOW")  # beam ok / beam interrupted / signal below threshold
LOW_SIGNAL_PCT = 25.0  # below this the instrument reports LOW

# Command words (the client sends them in upper case; the instrument accepts any case).
CMD_IDN = "*IDN?"
CMD_POS = "POS?"
CMD_ENV = "ENV?"
CMD_ZERO = "ZERO"
CMD_AVG = "AVG"
CMD_AVG_QUERY = "AVG?"

# Error codes of `ERR,<code>,<text>` replies.
ERR_UNKNOWN_COMMAND = 1
ERR_BAD_ARGUMENT = 2  # missing, extra or unparsable argument
ERR_BAD_AXIS = 3  # axis number outside 1..axes
ERR_OUT_OF_RANGE = 4  # argument parsed but outside its range (e.g. AVG above 10 s)
ERR_LINE_TOO_LONG = 5  # no terminator within MAX_LINE_BYTES
ERROR_NAMES = {
    ERR_UNKNOWN_COMMAND: "unknown command",
    ERR_BAD_ARGUMENT: "bad argument",
    ERR_BAD_AXIS: "bad axis",
    ERR_OUT_OF_RANGE: "argument out of range",
    ERR_LINE_TOO_LONG: "line too long",
}


class ProtocolError(ValueError):
    """A line that does not follow the protocol (framing, checksum, field count or type)."""


class InstrumentError(DriverError):
    """The instrument understood the frame but refused the command (an `ERR` reply).

    `code` is the protocol error code (see ERROR_NAMES); `instrument_text` its own message.
    """

    hint = "This is a usage or configuration error (axis count, argument range), not line noise."

    def __init__(self, message: str, code: int = 0, instrument_text: str = "", hint: str = ""):
        super().__init__(message, hint)
        self.code = code
        self.instrument_text = instrument_text


# -- framing -------------------------------------------------------------------------------


def checksum(body: bytes) -> str:
    """NMEA-style checksum of `body` (all bytes before '*'): XOR of the bytes, 2 upper hex."""
    # the bytes as one integer, folded in halves at byte boundaries (XOR pairs byte i with byte
    # i + half): a few big-integer operations instead of a Python step per byte (1 us, not 4,
    # for a 40-byte reply, on both ends of every exchange)
    value = int.from_bytes(body, "little")
    n = len(body)
    while n > 1:
        half = (n + 1) // 2
        value = (value & ((1 << (8 * half)) - 1)) ^ (value >> (8 * half))
        n = half
    return f"{value:02X}"


def frame_reply(*fields: object) -> bytes:
    """One reply line: fields joined by ',', then '*HH\\r\\n'."""
    body = ",".join(str(f) for f in fields).encode("ascii")
    return body + b"*" + checksum(body).encode("ascii") + TERMINATOR


def show_line(line: bytes, limit: int = 60) -> str:
    """repr of a received line for error messages, cut to `limit` bytes."""
    if len(line) <= limit:
        return repr(line)
    return repr(line[:limit]) + f"... ({len(line)} bytes)"


_PRINTABLE = bytes(range(0x20, 0x7F))


def split_reply(line: bytes) -> list[str]:
    """Check terminator, characters and checksum of one reply line; return its fields.

    Raises ProtocolError with the reason (the line itself is shown by the caller).
    """
    if not line:
        raise ProtocolError("empty reply")
    if not line.endswith(TERMINATOR):
        raise ProtocolError(f"reply not terminated by \\r\\n ({len(line)} bytes received before the timeout)")
    content = line[: -len(TERMINATOR)]
    if content.translate(None, _PRINTABLE):  # what is left is not printable ASCII (C speed: per reply)
        raise ProtocolError("reply contains non-printable or non-ASCII bytes (line noise?)")
    star = content.rfind(b"*")
    if star < 0:
        raise ProtocolError("reply has no '*HH' checksum")
    body, given = content[:star], content[star + 1 :]
    if len(given) != 2 or given.translate(None, b"0123456789ABCDEF"):  # something not uppercase hex left
        raise ProtocolError(f"checksum field {given.decode('ascii')!r} is not two uppercase hex digits")
    expected = checksum(body)
    if given.decode("ascii") != expected:
        raise ProtocolError(f"bad checksum: reply says {given.decode('ascii')}, computed {expected}")
    return body.decode("ascii").split(",")


# -- commands (client side builds them, instrument side parses them) ------------------------


def cmd_identity() -> bytes:
    return f"{CMD_IDN}\n".encode("ascii")


def cmd_position(axis: int) -> bytes:
    return f"{CMD_POS} {int(axis)}\n".encode("ascii")


def cmd_environment() -> bytes:
    return f"{CMD_ENV}\n".encode("ascii")


def cmd_zero(axis: int) -> bytes:
    return f"{CMD_ZERO} {int(axis)}\n".encode("ascii")


def cmd_set_averaging(averaging_s: float) -> bytes:
    return f"{CMD_AVG} {format_averaging(averaging_s)}\n".encode("ascii")


def cmd_averaging_query() -> bytes:
    return f"{CMD_AVG_QUERY}\n".encode("ascii")


def format_averaging(averaging_s: float) -> str:
    return f"{float(averaging_s):.3f}"


def parse_command(line: bytes) -> tuple[str, list[str]]:
    """Split one command line (without terminator) into upper-case word and arguments."""
    words = line.decode("ascii", errors="replace").strip().split()
    if not words:
        return "", []
    return words[0].upper(), words[1:]


# -- replies (instrument side formats them, client side parses them) ------------------------


@dataclass(frozen=True)
class PositionReply:
    """Fields of a `POS` reply: position (mm, relative to the axis zero, air-compensated),
    status (OK/BEAM/LOW), signal strength (0-100 %), instrument time (s)."""

    axis: int
    position_mm: float
    status: str
    signal_pct: float
    t_s: float


@dataclass(frozen=True)
class EnvironmentReply:
    air_temp_c: float
    air_pressure_hpa: float
    humidity_pct: float
    material_temp_c: tuple[float, ...]  # index 0 = axis (leg) 1; NaN = no sensor


def format_position(axis: int, position_mm: float, status: str, signal_pct: float, t_s: float) -> bytes:
    return frame_reply("POS", int(axis), f"{position_mm:+.9f}", status, f"{signal_pct:.1f}", f"{t_s:.6f}")


def format_environment(air_temp_c: float, air_pressure_hpa: float, humidity_pct: float, material_temp_c) -> bytes:
    temps = ["NAN" if math.isnan(t) else f"{t:.3f}" for t in material_temp_c]
    return frame_reply("ENV", f"{air_temp_c:.3f}", f"{air_pressure_hpa:.2f}", f"{humidity_pct:.1f}", *temps)


def format_error(code: int, text: str) -> bytes:
    # the text must not break the framing
    clean = "".join(c for c in text if 0x20 <= ord(c) <= 0x7E and c not in ",*")
    return frame_reply("ERR", int(code), clean)


def _number(fields: list[str], index: int, what: str, allow_nan: bool = False) -> float:
    text = fields[index]
    try:
        value = float(text)
    except ValueError:
        raise ProtocolError(f"field {index} ({what}) is {text!r}, not a number") from None
    if math.isinf(value) or (math.isnan(value) and not allow_nan):
        raise ProtocolError(f"field {index} ({what}) is {text!r}, not a finite number")
    return value


def _expect(fields: list[str], tag: str, count: int | None = None) -> None:
    if fields[0] != tag:
        raise ProtocolError(f"expected a {tag} reply, got {fields[0]!r}")
    if count is not None and len(fields) != count:
        raise ProtocolError(f"{tag} reply has {len(fields)} fields, expected {count}")


def raise_if_error(fields: list[str], command: str, port: str = "") -> None:
    """Raise InstrumentError for an `ERR,<code>,<text>` reply to `command` (sent on `port`)."""
    if fields and fields[0] == "ERR":
        try:
            code = int(fields[1]) if len(fields) > 1 else 0
        except ValueError:
            code = 0
        text = ",".join(fields[2:]) if len(fields) > 2 else ""
        name = ERROR_NAMES.get(code, "error")
        raise InstrumentError(
            f"interferometer{' on ' + port if port else ''} refused {command!r}: {name} (ERR {code}: {text}).",
            code=code,
            instrument_text=text,
        )


def parse_identity(fields: list[str]) -> str:
    """`IDN,<vendor>,<model>,<serial>,<firmware>` -> 'vendor,model,serial,firmware'."""
    _expect(fields, "IDN", 5)
    return ",".join(fields[1:])


def parse_position(fields: list[str], axis: int) -> PositionReply:
    _expect(fields, "POS", 6)
    try:
        got_axis = int(fields[1])
    except ValueError:
        raise ProtocolError(f"field 1 (axis) is {fields[1]!r}, not an integer") from None
    if got_axis != axis:
        # a late reply to an earlier query: the caller flushes and asks again
        raise ProtocolError(f"reply is for axis {got_axis}, asked for axis {axis}")
    status = fields[3]
    if status not in STATUSES:
        raise ProtocolError(f"field 3 (status) is {status!r}, expected one of {', '.join(STATUSES)}")
    signal = _number(fields, 4, "signal_pct")
    if not 0.0 <= signal <= 100.0:
        raise ProtocolError(f"field 4 (signal_pct) is {signal}, outside 0..100")
    return PositionReply(
        axis=got_axis,
        position_mm=_number(fields, 2, "position_mm"),
        status=status,
        signal_pct=signal,
        t_s=_number(fields, 5, "t_s"),
    )


def parse_environment(fields: list[str], axes: int) -> EnvironmentReply:
    _expect(fields, "ENV")
    if len(fields) != 4 + axes:
        raise ProtocolError(
            f"ENV reply has {len(fields) - 4} material temperatures, expected {axes} (one per axis)"
        )
    return EnvironmentReply(
        air_temp_c=_number(fields, 1, "air_temp_c"),
        air_pressure_hpa=_number(fields, 2, "air_pressure_hpa"),
        humidity_pct=_number(fields, 3, "humidity_pct"),
        material_temp_c=tuple(_number(fields, 4 + i, f"material_temp_c of axis {i + 1}", allow_nan=True) for i in range(axes)),
    )


def parse_ok(fields: list[str]) -> None:
    _expect(fields, "OK", 1)


def parse_averaging(fields: list[str]) -> float:
    _expect(fields, "AVG", 2)
    value = _number(fields, 1, "averaging_s")
    if not 0.0 <= value <= MAX_AVERAGING_S:
        raise ProtocolError(f"field 1 (averaging_s) is {value}, outside 0..{MAX_AVERAGING_S:g}")
    return value


# -- on-the-fly capture (docs/interferometer-protocol.md, "On-the-fly capture") ---------------
# The instrument latches one reading of an axis at each pulse on that axis' trigger input (wired
# to the drive's position-compare output), into a buffer the host reads after the pass.

CMD_CAP_ARM = "CAPARM"  # CAPARM <n> <count>: clear axis n's buffer, latch the next <count> pulses
CMD_CAP_COUNT = "CAPN?"  # CAPN? <n> -> CAPN,<n>,<captured>,<armed>
CMD_CAP_READ = "CAP?"  # CAP? <n> <i> -> CAP,<n>,<i>,<position_mm>,<status>,<signal_pct>,<t_s>
CMD_CAP_BLOCK = "CAPB?"  # CAPB? <n> <i> <count> -> CAPB,<n>,<i>,<k>, then k x (position, status, signal, t_s)
MAX_CAPTURE = 8192  # samples one axis buffers


@dataclass(frozen=True)
class CaptureSample:
    """Sample `index` (0-based, in trigger order) of a capture: the reading latched at the
    trigger pulse, `t_s` = instrument time of the pulse."""

    axis: int
    index: int
    position_mm: float
    status: str
    signal_pct: float
    t_s: float


def cmd_capture_arm(axis: int, count: int) -> bytes:
    return f"{CMD_CAP_ARM} {int(axis)} {int(count)}\n".encode("ascii")


def cmd_capture_count(axis: int) -> bytes:
    return f"{CMD_CAP_COUNT} {int(axis)}\n".encode("ascii")


def cmd_capture_read(axis: int, index: int) -> bytes:
    return f"{CMD_CAP_READ} {int(axis)} {int(index)}\n".encode("ascii")


def cmd_capture_block(axis: int, index: int, count: int) -> bytes:
    return f"{CMD_CAP_BLOCK} {int(axis)} {int(index)} {int(count)}\n".encode("ascii")


def format_capture_block(axis: int, index: int, samples: list[tuple[str, str, str, str]]) -> bytes:
    """A CAPB reply holding as many of `samples` (from sample `index` on, at least one) as fit in
    one line shorter than MAX_LINE_BYTES."""
    k = len(samples)
    while True:
        line = frame_reply("CAPB", int(axis), int(index), k, *(f for sample in samples[:k] for f in sample))
        if len(line) < MAX_LINE_BYTES or k == 1:
            return line
        k -= 1


def format_capture_count(axis: int, captured: int, armed: int) -> bytes:
    return frame_reply("CAPN", int(axis), int(captured), int(armed))


def format_capture_sample(axis: int, index: int, position: str, status: str, signal: str, t_s: str) -> bytes:
    """A CAP reply; the numbers are given as text (the simulator: fixed decimals like POS; a
    replay: the recorded values exactly)."""
    return frame_reply("CAP", int(axis), int(index), position, status, signal, t_s)


def _integer(fields: list[str], index: int, what: str) -> int:
    try:
        return int(fields[index])
    except ValueError:
        raise ProtocolError(f"field {index} ({what}) is {fields[index]!r}, not an integer") from None


def parse_capture_count(fields: list[str], axis: int) -> tuple[int, int]:
    """(captured, armed) of a CAPN reply for `axis`."""
    _expect(fields, "CAPN", 4)
    if _integer(fields, 1, "axis") != axis:
        raise ProtocolError(f"reply is for axis {fields[1]}, asked for axis {axis}")
    captured, armed = _integer(fields, 2, "captured"), _integer(fields, 3, "armed")
    if not 0 <= captured <= armed <= MAX_CAPTURE:
        raise ProtocolError(f"CAPN reply says {captured} of {armed} captured, not 0 <= captured <= armed <= {MAX_CAPTURE}")
    return captured, armed


def parse_capture_sample(fields: list[str], axis: int, index: int) -> CaptureSample:
    _expect(fields, "CAP", 7)
    if _integer(fields, 1, "axis") != axis or _integer(fields, 2, "index") != index:
        raise ProtocolError(f"reply is for axis {fields[1]} sample {fields[2]}, asked for axis {axis} sample {index}")
    return _capture_fields(fields, 3, axis, index)


def _capture_fields(fields: list[str], at: int, axis: int, index: int) -> CaptureSample:
    """The sample whose (position, status, signal, t_s) fields start at field `at`."""
    status = fields[at + 1]
    if status not in STATUSES:
        raise ProtocolError(f"field {at + 1} (status) is {status!r}, expected one of {', '.join(STATUSES)}")
    signal = _number(fields, at + 2, "signal_pct")
    if not 0.0 <= signal <= 100.0:
        raise ProtocolError(f"field {at + 2} (signal_pct) is {signal}, outside 0..100")
    return CaptureSample(axis, index, _number(fields, at, "position_mm"), status, signal, _number(fields, at + 3, "t_s"))


def parse_capture_block(fields: list[str], axis: int, index: int, count: int) -> list[CaptureSample]:
    """The samples of a CAPB reply to `CAPB? axis index count`: between 1 and `count` of them,
    from sample `index` on (the instrument sends as many as fit in one line)."""
    if not fields or fields[0] != "CAPB" or len(fields) < 8 or (len(fields) - 4) % 4:
        raise ProtocolError(f"expected a CAPB reply of 4 + 4 k fields, got {fields[:1]} with {len(fields)} fields")
    if _integer(fields, 1, "axis") != axis or _integer(fields, 2, "index") != index:
        raise ProtocolError(f"reply is for axis {fields[1]} sample {fields[2]}, asked for axis {axis} sample {index}")
    k = _integer(fields, 3, "count")
    if not 1 <= k <= count or len(fields) != 4 + 4 * k:
        raise ProtocolError(f"CAPB reply says {k} samples in {len(fields) - 4} fields; asked for at most {count}")
    return [_capture_fields(fields, 4 + 4 * j, axis, index + j) for j in range(k)]


# -- air compensation record (docs/interferometer-protocol.md, "Air compensation") -----------
# How the instrument turns fringe counts into millimetres: which refractive-index equation, from
# which air values, for which vacuum wavelength. The station records it in each session so the
# correction can be redone later (procedures/metrology/recorrect.py).

CMD_COMP = "COMP?"  # COMP? -> COMP,<mode>,<equation>,<wavelength_nm>,<air_temp_c>,<air_pressure_hpa>,<humidity_pct>,<co2_ppm>,<dead_path_mm>
COMP_MODES = ("AUTO", "MANUAL", "OFF")
"""AUTO: the index from the instrument's own air sensors at each reading (the values ENV? reports;
the air fields of COMP are NAN); MANUAL: from the fixed air values in the reply; OFF: none
(positions in vacuum wavelengths, n = 1)."""
COMP_EQUATIONS = ("EDLEN", "CIDDOR", "NONE")


@dataclass(frozen=True)
class CompensationReply:
    """The instrument's air compensation. Air values NaN in AUTO mode (per reading, from its
    sensors) and OFF mode; `co2_ppm` the CO2 its equation assumes; `dead_path_mm` the dead path it
    corrects for (0 = none)."""

    mode: str
    equation: str
    wavelength_nm: float
    air_temp_c: float
    air_pressure_hpa: float
    humidity_pct: float
    co2_ppm: float
    dead_path_mm: float

    def to_json(self) -> dict:
        """The record a session stores (NaN as None: JSON has no NaN)."""
        return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in self.__dict__.items()}


def cmd_compensation() -> bytes:
    return CMD_COMP.encode("ascii") + COMMAND_TERMINATOR


def _opt(value: float, spec: str) -> str:
    return "NAN" if value is None or (isinstance(value, float) and math.isnan(value)) else format(value, spec)


def format_compensation(c: CompensationReply) -> bytes:
    return frame_reply("COMP", c.mode, c.equation, f"{c.wavelength_nm:.4f}", _opt(c.air_temp_c, ".3f"),
                       _opt(c.air_pressure_hpa, ".2f"), _opt(c.humidity_pct, ".1f"), _opt(c.co2_ppm, ".1f"),
                       f"{c.dead_path_mm:.3f}")


def parse_compensation(fields: list[str]) -> CompensationReply:
    _expect(fields, "COMP", 9)
    mode, equation = fields[1], fields[2]
    if mode not in COMP_MODES:
        raise ProtocolError(f"field 1 (mode) is {mode!r}, expected one of {', '.join(COMP_MODES)}")
    if equation not in COMP_EQUATIONS:
        raise ProtocolError(f"field 2 (equation) is {equation!r}, expected one of {', '.join(COMP_EQUATIONS)}")
    if (mode == "OFF") != (equation == "NONE"):
        raise ProtocolError(f"mode {mode} with equation {equation}: OFF goes with NONE and only with it")
    wavelength = _number(fields, 3, "wavelength_nm")
    if not 400.0 <= wavelength <= 1700.0:
        raise ProtocolError(f"field 3 (wavelength_nm) is {wavelength}, outside 400..1700")
    air = [_number(fields, i, name, allow_nan=True) for i, name in
           ((4, "air_temp_c"), (5, "air_pressure_hpa"), (6, "humidity_pct"))]
    if mode == "MANUAL" and any(math.isnan(v) for v in air):
        raise ProtocolError("MANUAL compensation without its air values")
    return CompensationReply(mode, equation, wavelength, *air, co2_ppm=_number(fields, 7, "co2_ppm", allow_nan=True),
                             dead_path_mm=_number(fields, 8, "dead_path_mm"))
