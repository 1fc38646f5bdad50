"""What Modbus requests cost on an RTU line: frame bytes per function and the modelled wire time.

An RTU frame is address (1) + function (1) + data + CRC (2) bytes, each byte 11 bits on the
line (start, 8 data, parity or a second stop, stop), and a frame ends with 3.5 characters of
silence. One transaction is a request and its reply, plus the silence a drive's profile asks
for between frames (`[protocol] min_frame_gap_ms`, on top of RTU's own). Not modelled: the
drive's own time to answer (not in any manual we have) and the client's turnaround.

`WireTally` counts what a `ModbusBus` sent and received; `rtu_ms` turns a tally into
milliseconds on a line at `baud`. The bytes are those of the RTU frames a request would take
whatever the link really is (the simulated rig speaks Modbus TCP on loopback).
"""

from __future__ import annotations

from dataclasses import dataclass

RTU_BITS_PER_BYTE = 11
RTU_SILENCE_CHARS = 3.5

READ_HOLDING = 3
WRITE_MULTIPLE = 16
READ_WRITE_MULTIPLE = 23
READ_DEVICE_ID = 43  # MEI type 14, read once per session: its text objects are not counted


def rtu_frame_bytes(function: int, read_words: int = 0, write_words: int = 0) -> tuple[int, int]:
    """(request bytes, reply bytes) of one RTU transaction of `function` (3, 16, 23 or 43)."""
    if function == READ_HOLDING:  # addr fc start(2) count(2) crc(2); addr fc n data crc
        return 8, 5 + 2 * read_words
    if function == WRITE_MULTIPLE:  # addr fc start count n data crc; addr fc start count crc
        return 9 + 2 * write_words, 8
    if function == READ_WRITE_MULTIPLE:  # addr fc rstart rcount wstart wcount n data crc; as a read
        return 13 + 2 * write_words, 5 + 2 * read_words
    if function == READ_DEVICE_ID:  # addr fc mei code object crc; addr fc mei code conformity more next n crc
        return 7, 10
    raise ValueError(f"no RTU frame size for Modbus function {function}")


EXCEPTION_REPLY_BYTES = 5  # addr, fc | 0x80, code, crc


@dataclass
class WireTally:
    """Transactions and RTU bytes a bus sent (`bytes_out`) and received (`bytes_in`)."""

    transactions: int = 0
    bytes_out: int = 0
    bytes_in: int = 0

    def add(self, function: int, read_words: int = 0, write_words: int = 0, refused: bool = False) -> None:
        out, back = rtu_frame_bytes(function, read_words, write_words)
        self.transactions += 1
        self.bytes_out += out
        self.bytes_in += EXCEPTION_REPLY_BYTES if refused else back

    def copy(self) -> "WireTally":
        return WireTally(self.transactions, self.bytes_out, self.bytes_in)

    def __sub__(self, other: "WireTally") -> "WireTally":
        return WireTally(self.transactions - other.transactions, self.bytes_out - other.bytes_out,
                         self.bytes_in - other.bytes_in)

    @property
    def bytes(self) -> int:
        return self.bytes_out + self.bytes_in


def rtu_ms(tally: WireTally, baud: int, gap_ms: float = 0.0) -> float:
    """Modelled milliseconds of `tally` on an RTU line at `baud` (8 data bits, 11-bit
    characters): every byte, 3.5 characters of silence after each frame (request and reply),
    and `gap_ms` (the profile's min_frame_gap_ms) between transactions."""
    char_ms = RTU_BITS_PER_BYTE / baud * 1000.0
    return tally.bytes * char_ms + tally.transactions * (2 * RTU_SILENCE_CHARS * char_ms + gap_ms)
