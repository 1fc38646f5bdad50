"""Register encoding: integers of 16/32 bits, ASCII strings, and CRC-16/MODBUS.

Pure functions over lists of 16-bit register values, shared by the client and the simulated
drive so both sides agree bit for bit. 32-bit values span two registers; `word_order` "big"
puts the high word at the lower address (the Modbus convention most drives use), "little"
the low word.
"""

from __future__ import annotations

from typing import Sequence

TYPE_WORDS = {"u16": 1, "i16": 1, "u32": 2, "i32": 2}
_RANGES = {
    "u16": (0, 0xFFFF),
    "i16": (-0x8000, 0x7FFF),
    "u32": (0, 0xFFFFFFFF),
    "i32": (-0x80000000, 0x7FFFFFFF),
}
WORD_ORDERS = ("big", "little")


class CodecError(ValueError):
    """A value does not fit its register type."""


def int_range(typ: str) -> tuple[int, int]:
    """(min, max) of an integer register type."""
    return _RANGES[typ]


def encode_int(value: int, typ: str, word_order: str = "big") -> list[int]:
    """Registers holding integer `value` as register type `typ` (u16, i16, u32, i32)."""
    lo, hi = _RANGES[typ]
    value = int(value)
    if not lo <= value <= hi:
        raise CodecError(f"{value} does not fit a {typ} register (range {lo}..{hi})")
    if typ in ("u16", "i16"):
        return [value & 0xFFFF]
    raw = value & 0xFFFFFFFF
    words = [(raw >> 16) & 0xFFFF, raw & 0xFFFF]
    return words if word_order == "big" else words[::-1]


def decode_int(words: Sequence[int], typ: str, word_order: str = "big") -> int:
    """Integer held in `words` (1 or 2 registers) as register type `typ`."""
    n = TYPE_WORDS[typ]
    if len(words) != n:
        raise CodecError(f"a {typ} value needs {n} register(s), got {len(words)}")
    if n == 1:
        raw = int(words[0]) & 0xFFFF
        return raw - 0x10000 if typ == "i16" and raw & 0x8000 else raw
    hi, lo = (words[0], words[1]) if word_order == "big" else (words[1], words[0])
    raw = ((int(hi) & 0xFFFF) << 16) | (int(lo) & 0xFFFF)
    return raw - 0x100000000 if typ == "i32" and raw & 0x80000000 else raw


def encode_ascii(text: str, words: int) -> list[int]:
    """`text` as ASCII, two characters per register (first in the high byte), NUL padded."""
    data = text.encode("ascii", errors="replace")
    if len(data) > 2 * words:
        raise CodecError(f"text {text!r} is longer than {2 * words} characters")
    data = data.ljust(2 * words, b"\0")
    return [(data[i] << 8) | data[i + 1] for i in range(0, len(data), 2)]


def decode_ascii(words: Sequence[int]) -> str:
    """ASCII text held in registers (first character in the high byte); NULs and trailing
    spaces are dropped, non-printable bytes become '?'."""
    data = bytearray()
    for w in words:
        data += bytes(((int(w) >> 8) & 0xFF, int(w) & 0xFF))
    text = data.split(b"\0", 1)[0].decode("ascii", errors="replace")
    return "".join(c if c.isprintable() else "?" for c in text).rstrip()


def crc16_modbus(registers: Sequence[int]) -> int:
    """CRC-16/MODBUS (poly 0xA001 reflected, init 0xFFFF) over registers as big-endian bytes.

    The compensation-table checksum: computed over the entry registers as stored (forward
    entries, then reverse entries). The CRC of no registers is 0xFFFF.
    """
    crc = 0xFFFF
    for w in registers:
        for byte in ((int(w) >> 8) & 0xFF, int(w) & 0xFF):
            crc ^= byte
            for _ in range(8):
                crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


def chunks(address: int, values: Sequence[int], max_words: int) -> list[tuple[int, list[int]]]:
    """Split a write of `values` starting at `address` into (address, values) pieces of at most
    `max_words` registers (Modbus limits a write to 123 registers, a read to 125)."""
    out = []
    for i in range(0, len(values), max_words):
        out.append((address + i, list(values[i : i + max_words])))
    return out
