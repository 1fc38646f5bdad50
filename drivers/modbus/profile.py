"""Drive profiles: the register map of a servo drive, loaded from TOML and checked.

`DriveProfile.load()` reads `profiles/default.toml` (or a file you name) into frozen
dataclasses. Everything protocol-specific (addresses, types, word order, scaling, controlword
and statusword bits, fault codes, the compensation-table layout) comes from the file, so the
client and the simulated drive share one definition. Validation errors name the file and the
key, e.g. ``default.toml: [registers.position_actual] type: must be one of ...``.

`[protocol]` holds what a real drive's manual prescribes for the line: registers per read and
per write request, the silence between frames, the address base the manual prints, the unit id
of each leg, whether controlword and target may share one frame, how the new-set-point bit
latches, and what the drive does with a request longer than it accepts. `[scaling]` names the
counts per engineering unit (electronic gear, user units) that registers refer to by name.
A profile whose `[table]` says `kind = "none"` describes a drive without a compensation table
(`DriveProfile.table` is None). docs/drive-profiles.md lists every key.
"""

from __future__ import annotations

import math
import struct
import tomllib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from types import MappingProxyType
from typing import Any, Callable, Mapping, Sequence

from drivers.errors import DriverError
from drivers.states import DriveState
from drivers.modbus.codec import (
    TYPE_WORDS,
    WORD_ORDERS,
    CodecError,
    decode_ascii,
    decode_int,
    encode_ascii,
    encode_int,
)

_STRUCT_CODES = {"u16": "H", "i16": "h", "u32": "I", "i32": "i"}
"""Register type -> struct code (big-endian: a 32-bit value's high word first, word_order "big")."""

DEFAULT_PROFILE = Path(__file__).resolve().parent / "profiles" / "default.toml"

MAX_READ_WORDS = 125  # Modbus read_holding_registers limit (the protocol's, not a drive's)
MAX_WRITE_WORDS = 123  # Modbus write_registers limit (the protocol's, not a drive's)

# registers every drive must have: the CiA 402 state machine and the position
REQUIRED_REGISTERS = ("controlword", "target_position", "statusword", "position_actual")
# registers a drive with a compensation table must have
TABLE_REGISTERS = ("active_bank", "table_enable")
# registers a profile may map; where one is absent the client falls back on the profile
# ([identity], [limits]) or reports the value as not measured (NaN / 0)
OPTIONAL_REGISTERS = (
    "vendor", "product", "serial", "firmware", "map_version",
    "soft_limit_min", "soft_limit_max", "max_velocity", "max_acceleration",
    "profile_velocity", "profile_acceleration",
    "following_error", "fault_code", "axial_load", "modes_of_operation", "modes_of_operation_display",
    *TABLE_REGISTERS,
)  # fmt: skip
REQUIRED_BLOCKS = ("status",)
IDENTITY_REGISTERS = ("vendor", "product", "serial", "firmware", "map_version")
LIMIT_REGISTERS = ("soft_limit_min", "soft_limit_max", "max_velocity", "max_acceleration",
                   "profile_velocity", "profile_acceleration")
MOVE_WRITES = ("single", "target_then_controlword")
SET_POINT_LATCHES = ("level", "edge")
OVERSIZE_REPLIES = ("exception", "silence")
REQUIRED_CW_BITS = ("switch_on", "enable_voltage", "quick_stop", "enable_operation", "new_set_point", "fault_reset")
REQUIRED_COMMANDS = ("disable_voltage", "quick_stop", "shutdown", "switch_on", "enable_operation", "fault_reset")
REQUIRED_SW_BITS = (
    "ready_to_switch_on", "switched_on", "operation_enabled", "fault", "voltage_enabled",
    "quick_stop", "switch_on_disabled", "target_reached", "internal_limit_active",
    "set_point_acknowledge",
)  # fmt: skip
# control = "pr_trigger": a drive without a CiA 402 state machine on Modbus (Delta ASDA: servo
# on by a parameter, moves by triggering a stored position path, status from an output word)
CONTROLS = ("cia402", "pr_trigger")
PR_REGISTERS = ("servo_on", "pr_trigger", "fault_code")
PR_SW_BITS = ("servo_ready", "servo_on", "target_reached", "alarm")
PR_COMMANDS = ("servo_on", "servo_off", "run_path", "stop_path", "alarm_reset")
REQUIRED_HEADER = ("point_count", "start_position", "spacing", "units", "checksum", "valid")
REQUIRED_FAULTS = ("soft_limit",)


class ProfileError(DriverError, ValueError):
    """A drive profile file is missing, unreadable or inconsistent (a DriverError, so the
    command line shows it as one line)."""


@dataclass(frozen=True)
class Register:
    """One register (or group of registers holding one value).

    `scale` is engineering units per count (value = raw * scale, in `unit`); None for raw
    integers. `access` is "r" or "rw".
    """

    name: str
    address: int
    type: str  # u16 i16 u32 i32 ascii
    words: int
    scale: float | None = None
    unit: str = ""
    access: str = "r"
    word_order: str = "big"
    object: str = ""  # what the manual calls it (CiA 402 "6041h", Delta "P0-46"), for messages and docs

    @property
    def writable(self) -> bool:
        return self.access == "rw"

    @property
    def end(self) -> int:
        """First address after this register."""
        return self.address + self.words

    def counts(self, value: float) -> int:
        """Raw integer for engineering `value` (rounded to the nearest count); CodecError if it
        does not fit the register."""
        raw = round(value / self.scale) if self.scale else int(value)
        try:
            encode_int(raw, self.type, self.word_order)
        except CodecError as exc:
            raise CodecError(f"{self.name}: {value:g} {self.unit} is out of range ({exc})") from None
        return raw

    def encode(self, value: Any) -> list[int]:
        """Registers for an engineering value (str for ascii); CodecError as `counts` says."""
        if self.type == "ascii":
            return encode_ascii(str(value), self.words)
        raw = round(value / self.scale) if self.scale else int(value)
        try:  # encoded once (counts() would encode to check, then again)
            return encode_int(raw, self.type, self.word_order)
        except CodecError as exc:
            raise CodecError(f"{self.name}: {value:g} {self.unit} is out of range ({exc})") from None

    def decode(self, words: Sequence[int]) -> Any:
        """Engineering value (float when scaled, int otherwise, str for ascii) of `words`."""
        if self.type == "ascii":
            return decode_ascii(words)
        raw = decode_int(list(words), self.type, self.word_order)
        return raw * self.scale if self.scale else raw


@dataclass(frozen=True)
class Block:
    """Contiguous registers read or written by one request."""

    name: str
    start: int
    words: int
    names: tuple[str, ...]


@dataclass(frozen=True)
class FaultCode:
    code: int
    name: str
    text: str


@dataclass(frozen=True)
class ProfileLimits:
    """The limits a drive of this profile reports (the simulated drive serves these)."""

    soft_min_mm: float
    soft_max_mm: float
    max_velocity_mm_s: float
    max_accel_mm_s2: float
    profile_velocity_mm_s: float
    profile_accel_mm_s2: float


@dataclass(frozen=True)
class TableLayout:
    """Where the two compensation-table banks live and how entries are coded.

    Bank b: header at `bank_base[b]` (registers of `header`, addresses are offsets), forward
    entries at base + `fwd_offset`, reverse entries at base + `rev_offset`, `max_points` each.
    An entry is `entry_type` in `entry_scale_um` um per count.
    """

    max_points: int
    max_correction_um: float
    entry_type: str
    entry_scale_um: float
    units_code: int
    bank_base: tuple[int, ...]
    fwd_offset: int
    rev_offset: int
    header: Mapping[str, Register]  # address = offset from the bank base

    @property
    def banks(self) -> int:
        return len(self.bank_base)

    @cached_property  # asked on every write the simulated drive serves: computed once (frozen: never changes)
    def header_words(self) -> int:
        return max(r.end for r in self.header.values())

    def header_register(self, bank: int, name: str) -> Register:
        """Header register `name` of `bank` at its absolute address."""
        r = self.header[name]
        return Register(r.name, self.bank_base[bank] + r.address, r.type, r.words, r.scale, r.unit, r.access, r.word_order)

    def fwd_address(self, bank: int) -> int:
        return self.bank_base[bank] + self.fwd_offset

    def rev_address(self, bank: int) -> int:
        return self.bank_base[bank] + self.rev_offset

    def bank_end(self, bank: int) -> int:
        """First address after the bank."""
        return self.bank_base[bank] + self._bank_words

    @cached_property
    def _bank_words(self) -> int:
        return max(self.header_words, self.fwd_offset + self.max_points, self.rev_offset + self.max_points)

    def entry_counts(self, error_um: float) -> int:
        """Raw entry for an error in um (rounded to the entry resolution)."""
        return round(error_um / self.entry_scale_um)

    def decode_header(self, words: Sequence[int]) -> dict[str, Any]:
        """Header values from the `header_words` registers at the bank base."""
        return {n: r.decode(words[r.address : r.end]) for n, r in self.header.items()}

    def encode_header(self, values: Mapping[str, Any]) -> list[int]:
        """`header_words` registers for header `values` (missing names are 0)."""
        out = [0] * self.header_words
        for n, r in self.header.items():
            out[r.address : r.end] = r.encode(values.get(n, 0))
        return out


@dataclass(frozen=True)
class ProtocolSettings:
    """How a drive wants to be talked to on the line ([protocol] of the profile).

    `max_read_words` / `max_write_words`: the longest request the drive accepts (the client
    splits longer ones; a 32-bit value is never split across two requests).
    `min_frame_gap_ms`: silence the drive needs between the end of one frame and the next
    request (the client waits it; RTU's own 3.5 characters come on top).
    `address_base`: 0 when the profile's addresses are PDU addresses as sent on the wire, 1 when
    they are printed 1-based (register 1 = PDU address 0) like many manuals do; the loaded
    Register.address is always the PDU address.
    `unit_ids`: leg -> Modbus unit id; None = unit id = leg number.
    `move_write`: "single" = controlword and target in one write (the drive latches the target
    with the controlword); "target_then_controlword" = the target is written first, then the
    controlword (for drives whose objects are not contiguous).
    `set_point_latch`: "level" = every controlword write with new_set_point set starts a move;
    "edge" = only a rising edge does (CiA 402), so the client clears the bit after each move.
    `oversize_reply`: what the drive does with a request longer than allowed: "exception"
    (Modbus exception 03, illegal data value) or "silence" (no reply).
    `mode_of_operation`: value the client writes to modes_of_operation before enabling
    (1 = CiA 402 profile position mode); None = the drive has no such register.
    `device_identification`: the drive answers Modbus Read Device Identification (function 43,
    MEI type 14: vendor, product code, revision); False when its manual does not say so (the
    station then takes the drive's identity from the config).
    `read_write_multiple`: the drive serves function 23 (read/write multiple registers, the
    write done before the read): a move's write and the status read after it go in one
    transaction. False (the default) when the manual does not say it does; the simulated drive
    then refuses function 23 with exception 01, as such a drive would.
    """

    max_read_words: int = MAX_READ_WORDS
    max_write_words: int = MAX_WRITE_WORDS
    min_frame_gap_ms: float = 0.0
    address_base: int = 0
    unit_ids: Mapping[int, int] | None = None
    move_write: str = "single"
    set_point_latch: str = "level"
    oversize_reply: str = "exception"
    mode_of_operation: int | None = None
    device_identification: bool = False
    read_write_multiple: bool = False

    def unit_id(self, leg: int) -> int:
        """Modbus unit id of `leg`; ProfileError if the profile's table has no entry for it."""
        if self.unit_ids is None:
            return int(leg)
        try:
            return self.unit_ids[int(leg)]
        except KeyError:
            raise ProfileError(f"[protocol] unit_ids has no unit id for leg {leg}; add `{leg} = <unit id>` "
                               "to the drive profile") from None


@dataclass(frozen=True)
class DriveProfile:
    """A drive's register map and semantics. Load with `DriveProfile.load(path=None)`.

    `table` is None for a drive that holds no compensation table ([table] kind = "none");
    `table_note` then says why (shown to the user)."""

    path: str
    name: str
    map_version: int
    word_order: str
    limits: ProfileLimits
    identity: Mapping[str, str]
    registers: Mapping[str, Register]
    blocks: Mapping[str, Block]
    controlword_bits: Mapping[str, int]
    commands: Mapping[str, int]
    statusword_bits: Mapping[str, int]
    faults: Mapping[int, FaultCode]
    table: TableLayout | None
    protocol: ProtocolSettings = field(default_factory=ProtocolSettings)
    scaling: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))
    table_note: str = ""
    control: str = "cia402"  # or "pr_trigger" (see CONTROLS)

    @property
    def has_table(self) -> bool:
        return self.table is not None

    def has(self, name: str) -> bool:
        """Whether the profile maps register `name`."""
        return name in self.registers

    def runs(self, names: Sequence[str], max_words: int | None = None) -> list[tuple[int, int, tuple[str, ...]]]:
        """(address, words, register names) of the requests that read registers `names`:
        contiguous registers share a request of at most `max_words` (default: the profile's
        max_read_words); a register is never split across two requests."""
        limit = max_words or self.protocol.max_read_words
        regs = sorted((self.registers[n] for n in names), key=lambda r: r.address)
        out: list[tuple[int, int, tuple[str, ...]]] = []
        for r in regs:
            if out:
                a, w, ns = out[-1]
                if a + w == r.address and w + r.words <= limit:
                    out[-1] = (a, w + r.words, ns + (r.name,))
                    continue
            out.append((r.address, r.words, (r.name,)))
        return out

    def run_decoder(self, names: Sequence[str]) -> Callable[[Sequence[int]], dict[str, Any]]:
        """The words of one run (contiguous registers `names`, as `runs` gives them, its first
        address first) -> {name: engineering value}, the values `Register.decode` gives. Integer
        registers in big word order are unpacked with one struct call (a status read per point:
        several times faster than register by register); others register by register."""
        regs = sorted((self.registers[n] for n in names), key=lambda r: r.address)
        a0 = regs[0].address

        def one_by_one(words: Sequence[int]) -> dict[str, Any]:
            return {r.name: r.decode(words[r.address - a0 : r.end - a0]) for r in regs}

        if any(r.type not in _STRUCT_CODES or (r.words > 1 and r.word_order != "big") for r in regs) or any(
                b.address != a.end for a, b in zip(regs, regs[1:])):
            return one_by_one
        packer = struct.Struct(f">{sum(r.words for r in regs)}H")
        unpacker = struct.Struct(">" + "".join(_STRUCT_CODES[r.type] for r in regs))
        order = tuple(r.name for r in regs)
        scaled = tuple((r.name, r.scale) for r in regs if r.scale)

        def decode(words: Sequence[int]) -> dict[str, Any]:
            try:
                out = dict(zip(order, unpacker.unpack(packer.pack(*words))))
            except struct.error:  # not 16-bit words, or not as many: as `Register.decode` takes them
                return one_by_one(words)
            for name, scale in scaled:
                out[name] *= scale
            return out

        return decode

    # -- loading ------------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | Path | None = None) -> "DriveProfile":
        """Read and check a profile TOML; None = the built-in `profiles/default.toml`.

        Raises ProfileError naming the file and key on any problem.
        """
        p = Path(path) if path else DEFAULT_PROFILE
        if not p.is_file():
            raise ProfileError(f"drive profile {p} not found; give the path of a profile TOML "
                               f"(the built-in one is {DEFAULT_PROFILE})")
        try:
            data = tomllib.loads(p.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise ProfileError(f"{p}: not valid TOML ({exc}); fix the file") from None
        return _Parser(p, data).profile()

    # -- lookups ------------------------------------------------------------------------------
    def register(self, name: str) -> Register:
        try:
            return self.registers[name]
        except KeyError:
            raise ProfileError(f"{self.path}: no register named {name!r}") from None

    def address(self, name: str) -> int:
        """0-based holding-register address of register `name` (mbpoll: use -0)."""
        return self.register(name).address

    def fault(self, code: int) -> FaultCode | None:
        return self.faults.get(code)

    def fault_by_name(self, name: str) -> FaultCode:
        for f in self.faults.values():
            if f.name == name:
                return f
        raise ProfileError(f"{self.path}: no fault named {name!r} in [[fault]]")

    def fault_text(self, code: int) -> str:
        """Human text of a fault code, e.g. '0x8612 soft_limit: target beyond ...'."""
        f = self.faults.get(code)
        return f"0x{code:04X} {f.name}: {f.text}" if f else f"0x{code:04X} (not in profile {self.name})"

    def sw_bit(self, statusword: int, name: str) -> bool:
        return bool(statusword >> self.statusword_bits[name] & 1)

    def cw_bit(self, controlword: int, name: str) -> bool:
        return bool(controlword >> self.controlword_bits[name] & 1)

    def state_of(self, statusword: int) -> DriveState:
        """CiA 402 state of a statusword (see drivers.interfaces.DriveStatus.state). For a
        `pr_trigger` drive the "statusword" is its servo output status: alarm = fault, servo on
        = operation enabled, otherwise switch on disabled (ready) or not ready."""
        bit = lambda n: self.sw_bit(statusword, n)  # noqa: E731
        if self.control == "pr_trigger":
            if bit("alarm"):
                return DriveState.FAULT
            if bit("servo_on"):
                return DriveState.OPERATION_ENABLED
            return DriveState.SWITCH_ON_DISABLED if bit("servo_ready") else DriveState.NOT_READY
        if bit("fault"):
            return DriveState.FAULT
        if bit("switch_on_disabled"):
            return DriveState.SWITCH_ON_DISABLED
        if bit("operation_enabled"):
            return DriveState.OPERATION_ENABLED if bit("quick_stop") else DriveState.QUICK_STOP_ACTIVE
        if bit("switched_on"):
            return DriveState.SWITCHED_ON
        if bit("ready_to_switch_on"):
            return DriveState.READY_TO_SWITCH_ON
        return DriveState.NOT_READY

    def statusword_of(self, state: DriveState | str, **flags: bool) -> int:
        """The statusword a drive in `state` reports, with extra bits (`target_reached=True`, ...).

        Bit patterns as CiA 402 (voltage_enabled follows the power stage); for a `pr_trigger`
        drive its servo output status (a quick-stopped one is servo off, ready).
        """
        if self.control == "pr_trigger":
            on = {
                DriveState.NOT_READY: (),
                DriveState.OPERATION_ENABLED: ("servo_ready", "servo_on"),
                DriveState.FAULT: ("alarm",),
            }.get(DriveState(state), ("servo_ready",))
        else:
            on = None
        on = on if on is not None else {
            DriveState.NOT_READY: (),
            DriveState.SWITCH_ON_DISABLED: ("switch_on_disabled", "quick_stop"),
            DriveState.READY_TO_SWITCH_ON: ("ready_to_switch_on", "quick_stop", "voltage_enabled"),
            DriveState.SWITCHED_ON: ("ready_to_switch_on", "switched_on", "quick_stop", "voltage_enabled"),
            DriveState.OPERATION_ENABLED: ("ready_to_switch_on", "switched_on", "operation_enabled", "quick_stop", "voltage_enabled"),
            DriveState.QUICK_STOP_ACTIVE: ("ready_to_switch_on", "switched_on", "operation_enabled", "voltage_enabled"),
            DriveState.FAULT: ("fault",),
        }[DriveState(state)]
        word = 0
        for n in on:
            word |= 1 << self.statusword_bits[n]
        for n, v in flags.items():
            if v and n in self.statusword_bits:
                word |= 1 << self.statusword_bits[n]
        return word


class _Parser:
    """Turns the TOML dict into a DriveProfile, naming file and key in every error."""

    def __init__(self, path: Path, data: dict):
        self.path = path
        self.data = data
        self.scaling: dict[str, float] = {}
        self.address_base = 0

    def err(self, key: str, what: str) -> ProfileError:
        return ProfileError(f"{self.path}: [{key}] {what}; fix the drive profile")

    def section(self, key: str) -> dict:
        sec = self.data.get(key)
        if not isinstance(sec, dict):
            raise self.err(key, "section missing")
        return sec

    def num(self, sec: dict, key: str, name: str, positive: bool = False) -> float:
        v = sec.get(name)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.err(key, f"{name}: must be a number, got {v!r}")
        if not math.isfinite(v):  # inf/nan are TOML numbers; no limit or scale is infinite
            raise self.err(key, f"{name}: must be a finite number, got {v!r}")
        if positive and not v > 0:
            raise self.err(key, f"{name}: must be > 0, got {v!r}")
        return float(v)

    def integer(self, sec: dict, key: str, name: str, lo: int = 0, hi: int = 0xFFFF) -> int:
        v = sec.get(name)
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise self.err(key, f"{name}: must be an integer in {lo}..{hi}, got {v!r}")
        return v

    def choice(self, sec: dict, key: str, name: str, options: Sequence[str], default: str) -> str:
        v = sec.get(name, default)
        if v not in options:
            raise self.err(key, f"{name}: must be one of {', '.join(repr(o) for o in options)}, got {v!r}")
        return v

    def reg(self, key: str, name: str, spec: Any, word_order: str, addr_key: str = "address") -> Register:
        if not isinstance(spec, dict):
            raise self.err(key, f"must be a table like {{ {addr_key} = 100, type = \"u16\" }}")
        typ = spec.get("type")
        if typ not in (*TYPE_WORDS, "ascii"):
            raise self.err(key, f"type: must be one of u16, i16, u32, i32, ascii, got {typ!r}")
        if addr_key == "address":
            # as printed in the manual; on the wire it is printed - address_base
            printed = self.integer(spec, key, addr_key, self.address_base, 0xFFFF + self.address_base)
            address = printed - self.address_base
        else:
            address = self.integer(spec, key, addr_key)
        if typ == "ascii":
            words = self.integer(spec, key, "words", 1, 60)
        else:
            words = TYPE_WORDS[typ]
        scale = spec.get("scale")
        if isinstance(scale, str):
            # a [scaling] entry: counts per engineering unit, so one count is 1/that
            if scale not in self.scaling:
                raise self.err(key, f"scale: {scale!r} is not a key of [scaling] (known: {', '.join(self.scaling) or 'none'})")
            scale = 1.0 / self.scaling[scale]
        elif scale is not None:
            scale = self.num(spec, key, "scale", positive=True)
        if scale is not None and typ == "ascii":
            raise self.err(key, "scale: not allowed for ascii")
        access = spec.get("access", "rw" if addr_key == "offset" else "r")
        if access not in ("r", "rw"):
            raise self.err(key, f"access: must be \"r\" or \"rw\", got {access!r}")
        unit = spec.get("unit", "")
        if not isinstance(unit, str):
            raise self.err(key, f"unit: must be a string, got {unit!r}")
        obj = spec.get("object", "")
        if not isinstance(obj, str):
            raise self.err(key, f"object: must be a string such as \"6041h\" or \"P0-46\", got {obj!r}")
        if address + words > 0x10000:
            raise self.err(key, f"{addr_key}: {address} + {words} words runs past 65535")
        return Register(name, address, typ, words, scale, unit, access, word_order, obj)

    def bits(self, key: str, required: Sequence[str], hi: int) -> dict[str, int]:
        sec = self.section(key)
        out = {}
        for n, v in sec.items():
            out[n] = self.integer(sec, key, n, 0, hi)
        missing = [n for n in required if n not in out]
        if missing:
            raise self.err(key, f"missing {', '.join(missing)}")
        return out

    def protocol(self) -> ProtocolSettings:
        """[protocol]: optional; every key has the default of a drive that accepts whatever
        Modbus carries (the built-in simulated drive)."""
        sec = self.data.get("protocol", {})
        if not isinstance(sec, dict):
            raise self.err("protocol", "must be a table")
        known = {"max_read_words", "max_write_words", "min_frame_gap_ms", "address_base", "unit_ids", "move_write",
                 "set_point_latch", "oversize_reply", "mode_of_operation", "device_identification",
                 "read_write_multiple"}
        unknown = sorted(set(sec) - known)
        if unknown:
            raise self.err("protocol", f"unknown key(s) {', '.join(unknown)} (known: {', '.join(sorted(known))})")
        g = lambda n, d: sec.get(n, d)  # noqa: E731
        max_read = self._int_default(sec, "max_read_words", MAX_READ_WORDS, 1, MAX_READ_WORDS)
        max_write = self._int_default(sec, "max_write_words", MAX_WRITE_WORDS, 1, MAX_WRITE_WORDS)
        gap = g("min_frame_gap_ms", 0.0)
        if isinstance(gap, bool) or not isinstance(gap, (int, float)) or not 0 <= gap <= 1000:
            raise self.err("protocol", f"min_frame_gap_ms: must be a number of milliseconds 0..1000, got {gap!r}")
        base = self._int_default(sec, "address_base", 0, 0, 1)
        units = g("unit_ids", "leg")
        unit_ids: dict[int, int] | None
        if units == "leg":
            unit_ids = None
        elif isinstance(units, dict) and units:
            unit_ids = {}
            for k, v in units.items():
                if not (isinstance(k, str) and k.isdigit() and 1 <= int(k) <= 247):
                    raise self.err("protocol.unit_ids", f"key {k!r}: must be a leg number 1..247")
                if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 247:
                    raise self.err("protocol.unit_ids", f"{k}: unit id must be an integer 1..247, got {v!r}")
                unit_ids[int(k)] = v
            if len(set(unit_ids.values())) != len(unit_ids):
                raise self.err("protocol.unit_ids", "two legs share a unit id; each drive needs its own")
        else:
            raise self.err("protocol", f"unit_ids: must be \"leg\" (unit id = leg number) or a table "
                                       f"{{ 1 = 11, 2 = 12, ... }}, got {units!r}")
        mode = g("mode_of_operation", None)
        if mode is not None and (isinstance(mode, bool) or not isinstance(mode, int) or not -128 <= mode <= 127):
            raise self.err("protocol", f"mode_of_operation: must be an integer -128..127 (1 = profile position), got {mode!r}")
        device_id = g("device_identification", False)
        if not isinstance(device_id, bool):
            raise self.err("protocol", f"device_identification: must be true or false (does the drive answer "
                                       f"Modbus function 43/14?), got {device_id!r}")
        rw_multiple = g("read_write_multiple", False)
        if not isinstance(rw_multiple, bool):
            raise self.err("protocol", f"read_write_multiple: must be true or false (does the drive serve Modbus "
                                       f"function 23?), got {rw_multiple!r}")
        self.address_base = base
        return ProtocolSettings(
            max_read_words=max_read, max_write_words=max_write, min_frame_gap_ms=float(gap), address_base=base,
            unit_ids=MappingProxyType(unit_ids) if unit_ids is not None else None,
            move_write=self.choice(sec, "protocol", "move_write", MOVE_WRITES, "single"),
            set_point_latch=self.choice(sec, "protocol", "set_point_latch", SET_POINT_LATCHES, "level"),
            oversize_reply=self.choice(sec, "protocol", "oversize_reply", OVERSIZE_REPLIES, "exception"),
            mode_of_operation=mode, device_identification=device_id, read_write_multiple=rw_multiple,
        )  # fmt: skip

    def _int_default(self, sec: dict, name: str, default: int, lo: int, hi: int) -> int:
        return self.integer(sec, "protocol", name, lo, hi) if name in sec else default

    def scaling_section(self) -> dict[str, float]:
        sec = self.data.get("scaling", {})
        if not isinstance(sec, dict):
            raise self.err("scaling", "must be a table of counts per unit, e.g. position_counts_per_mm = 10000")
        return {n: self.num(sec, "scaling", n, positive=True) for n in sec}

    def profile(self) -> DriveProfile:
        prof = self.section("profile")
        word_order = prof.get("word_order", "big")
        if word_order not in WORD_ORDERS:
            raise self.err("profile", f"word_order: must be \"big\" or \"little\", got {word_order!r}")
        name = prof.get("name")
        if not isinstance(name, str) or not name:
            raise self.err("profile", "name: must be a non-empty string")
        map_version = self.integer(prof, "profile", "map_version")
        control = self.choice(prof, "profile", "control", CONTROLS, "cia402")
        protocol = self.protocol()
        self.scaling = self.scaling_section()

        lim = self.section("limits")
        limits = ProfileLimits(
            soft_min_mm=self.num(lim, "limits", "soft_min_mm"),
            soft_max_mm=self.num(lim, "limits", "soft_max_mm"),
            max_velocity_mm_s=self.num(lim, "limits", "max_velocity_mm_s", positive=True),
            max_accel_mm_s2=self.num(lim, "limits", "max_accel_mm_s2", positive=True),
            profile_velocity_mm_s=self.num(lim, "limits", "profile_velocity_mm_s", positive=True),
            profile_accel_mm_s2=self.num(lim, "limits", "profile_accel_mm_s2", positive=True),
        )
        if not limits.soft_min_mm < limits.soft_max_mm:
            raise self.err("limits", f"soft_min_mm ({limits.soft_min_mm}) must be below soft_max_mm ({limits.soft_max_mm})")

        ident_sec = self.section("identity")
        identity = {}
        for n in ("vendor", "product", "firmware", "serial_prefix"):
            v = ident_sec.get(n)
            if not isinstance(v, str) or not v.isascii():
                raise self.err("identity", f"{n}: must be an ASCII string, got {v!r}")
            identity[n] = v

        regs_sec = self.section("registers")
        registers = {n: self.reg(f"registers.{n}", n, spec, word_order) for n, spec in regs_sec.items()}
        required = REQUIRED_REGISTERS if control == "cia402" else \
            ("target_position", "statusword", "position_actual", *PR_REGISTERS)
        missing = [n for n in required if n not in registers]
        if missing:
            raise self.err("registers", f"missing {', '.join(missing)}")
        for n in ("statusword" if control == "cia402" else "", "controlword", "active_bank", "table_enable", "map_version"):
            if n in registers and registers[n].type != "u16":
                raise self.err(f"registers.{n}", f"type: must be u16, got {registers[n].type}")
        if "fault_code" in registers and registers["fault_code"].type not in ("u16", "u32"):
            raise self.err("registers.fault_code", f"type: must be u16 or u32, got {registers['fault_code'].type}")
        writable = ("servo_on", "pr_trigger", "fault_code") if control == "pr_trigger" else ()
        for n in ("controlword", "target_position", "active_bank", "table_enable", "modes_of_operation", *writable):
            if n in registers and not registers[n].writable:
                raise self.err(f"registers.{n}", "access: must be \"rw\" (the station writes it)")
        for n in ("vendor", "product", "serial", "firmware"):
            if n in registers and registers[n].type != "ascii":
                raise self.err(f"registers.{n}", "type: must be ascii")
        if ("modes_of_operation" in registers) != (protocol.mode_of_operation is not None):
            raise self.err("protocol", "mode_of_operation and [registers.modes_of_operation] go together: "
                                       "give both (a drive with operating modes) or neither")
        ordered = sorted(registers.values(), key=lambda r: r.address)
        for a, b in zip(ordered, ordered[1:]):
            if b.address < a.end:
                raise self.err(f"registers.{b.name}", f"address: {b.address} overlaps {a.name} ({a.address}..{a.end - 1})")
        for r in registers.values():
            if r.words > min(protocol.max_read_words, protocol.max_write_words if r.writable else MAX_WRITE_WORDS):
                raise self.err(f"registers.{r.name}", f"{r.words} words do not fit one request of this drive "
                                                      f"([protocol] max_read_words / max_write_words)")

        blocks_sec = self.section("blocks")
        blocks = {}
        for bname, names in blocks_sec.items():
            key = f"blocks.{bname}"
            if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
                raise self.err(key, "must be a list of register names")
            unknown = [n for n in names if n not in registers]
            if unknown:
                raise self.err(key, f"unknown register(s) {', '.join(unknown)}")
            rs = sorted((registers[n] for n in names), key=lambda r: r.address)
            words = rs[-1].end - rs[0].address
            if bname == "move_command":
                # one frame carries it: it must be contiguous and fit one write of this drive
                for a, b in zip(rs, rs[1:]):
                    if b.address != a.end:
                        raise self.err(key, f"registers must be contiguous (one write carries them): gap between "
                                            f"{a.name} and {b.name}; or set [protocol] move_write = \"target_then_controlword\"")
                if words > protocol.max_write_words:
                    raise self.err(key, f"spans {words} registers, more than one write of this drive carries "
                                        f"([protocol] max_write_words = {protocol.max_write_words})")
            elif bname in ("identity", "limits", "status") and all(b.address == a.end for a, b in zip(rs, rs[1:])) \
                    and words > MAX_READ_WORDS:
                raise self.err(key, f"spans {words} registers, more than one request carries ({MAX_READ_WORDS})")
            blocks[bname] = Block(bname, rs[0].address, words, tuple(r.name for r in rs))
        missing = [n for n in REQUIRED_BLOCKS if n not in blocks]
        if missing:
            raise self.err("blocks", f"missing {', '.join(missing)}")
        if control == "pr_trigger" and protocol.move_write != "target_then_controlword":
            raise self.err("protocol", "move_write: a pr_trigger drive gets the target, then the trigger: "
                                       "set move_write = \"target_then_controlword\"")
        if protocol.move_write == "single":
            if "move_command" not in blocks:
                raise self.err("blocks", "missing move_command (controlword + target_position in one write); or set "
                                         "[protocol] move_write = \"target_then_controlword\"")
            if blocks["move_command"].names[0] != "controlword" or "target_position" not in blocks["move_command"].names:
                raise self.err("blocks.move_command", "controlword must come first, then target_position (the drive "
                                                      "latches the target on the controlword write)")
        if "statusword" not in blocks["status"].names:
            raise self.err("blocks.status", "must include statusword")
        for bname, want in (("identity", IDENTITY_REGISTERS), ("limits", LIMIT_REGISTERS)):
            if bname not in blocks:
                # derived: the registers of that kind the profile maps
                names = tuple(n for n in want if n in registers)
                if names:
                    rs = sorted((registers[n] for n in names), key=lambda r: r.address)
                    blocks[bname] = Block(bname, rs[0].address, rs[-1].end - rs[0].address, tuple(r.name for r in rs))

        if control == "cia402":
            cw_bits = self.bits("controlword", REQUIRED_CW_BITS, 15)
            commands = self.bits("commands", REQUIRED_COMMANDS, 0xFFFF)
            sw_bits = self.bits("statusword", REQUIRED_SW_BITS, 15)
        else:
            cw_bits = {}
            commands = self.bits("commands", PR_COMMANDS, 0xFFFF)
            sw_bits = self.bits("statusword", PR_SW_BITS, 31 if registers["statusword"].words == 2 else 15)

        faults_list = self.data.get("fault", [])
        if not isinstance(faults_list, list):
            raise self.err("fault", "must be an array of tables ([[fault]])")
        faults = {}
        for i, f in enumerate(faults_list):
            key = f"fault #{i + 1}"
            if not isinstance(f, dict):
                raise self.err(key, "must be a table with code, name, text")
            code = self.integer(f, key, "code", 1, 0xFFFF)
            fname, text = f.get("name"), f.get("text")
            if not isinstance(fname, str) or not isinstance(text, str):
                raise self.err(key, "name and text must be strings")
            if code in faults:
                raise self.err(key, f"code 0x{code:04X} defined twice")
            faults[code] = FaultCode(code, fname, text)
        missing = [n for n in REQUIRED_FAULTS if n not in {f.name for f in faults.values()}]
        if missing:
            raise self.err("fault", f"missing fault(s) named {', '.join(missing)}")

        table, note = self.table(word_order, registers)
        return DriveProfile(
            path=str(self.path), name=name, map_version=map_version, word_order=word_order,
            limits=limits, identity=MappingProxyType(identity), registers=MappingProxyType(registers),
            blocks=MappingProxyType(blocks), controlword_bits=MappingProxyType(cw_bits),
            commands=MappingProxyType(commands), statusword_bits=MappingProxyType(sw_bits),
            faults=MappingProxyType(faults), table=table, protocol=protocol,
            scaling=MappingProxyType(dict(self.scaling)), table_note=note, control=control,
        )  # fmt: skip

    def table(self, word_order: str, registers: dict[str, Register]) -> tuple[TableLayout | None, str]:
        sec = self.section("table")
        kind = self.choice(sec, "table", "kind", ("banks", "none"), "banks")
        if kind == "none":
            note = sec.get("note", "")
            if not isinstance(note, str) or not note.strip():
                raise self.err("table", "note: say why the drive holds no table (e.g. \"no compensation table over "
                                        "Modbus in the manual\"), so the station can tell the user")
            extra = sorted(set(sec) - {"kind", "note"})
            if extra:
                raise self.err("table", f"kind = \"none\" takes only a note, not {', '.join(extra)}")
            return None, note.strip()
        missing = [n for n in TABLE_REGISTERS if n not in registers]
        if missing:
            raise self.err("registers", f"missing {', '.join(missing)} (a drive with table banks needs them; "
                                        "or set [table] kind = \"none\")")
        max_points = self.integer(sec, "table", "max_points", 2, 4096)
        max_corr = self.num(sec, "table", "max_correction_um", positive=True)
        entry_type = sec.get("entry_type")
        if entry_type != "i16":
            raise self.err("table", f"entry_type: only \"i16\" is supported, got {entry_type!r}")
        scale = self.num(sec, "table", "entry_scale_um", positive=True)
        if not max_corr / scale < 0x7FFF + 0.5:  # (rounds above 0x7FFF; also a quotient overflowing to inf)
            raise self.err("table", f"max_correction_um {max_corr} does not fit an i16 entry of {scale} um")
        units_code = self.integer(sec, "table", "units_code")
        bases = sec.get("bank_base")
        if not isinstance(bases, list) or len(bases) != 2 or not all(isinstance(b, int) and not isinstance(b, bool) for b in bases):
            raise self.err("table", f"bank_base: must be a list of two addresses, got {bases!r}")
        bases = [b - self.address_base for b in bases]
        fwd = self.integer(sec, "table", "fwd_offset")
        rev = self.integer(sec, "table", "rev_offset")
        hsec = sec.get("header")
        if not isinstance(hsec, dict):
            raise self.err("table.header", "section missing")
        header = {n: self.reg(f"table.header.{n}", n, spec, word_order, addr_key="offset") for n, spec in hsec.items()}
        missing = [n for n in REQUIRED_HEADER if n not in header]
        if missing:
            raise self.err("table.header", f"missing {', '.join(missing)}")
        layout = TableLayout(max_points, max_corr, entry_type, scale, units_code, tuple(bases), fwd, rev, MappingProxyType(header))
        hw = layout.header_words
        spans = sorted([(0, hw, "header"), (fwd, fwd + max_points, "fwd entries"), (rev, rev + max_points, "rev entries")])
        for (a0, a1, an), (b0, _b1, bn) in zip(spans, spans[1:]):
            if b0 < a1:
                raise self.err("table", f"{bn} (offset {b0}) overlap {an} (ends at offset {a1 - 1})")
        used = [(r.address, r.end, f"registers.{r.name}") for r in registers.values()]
        for b in range(2):
            used.append((layout.bank_base[b], layout.bank_end(b), f"table bank {b}"))
        used.sort()
        for (a0, a1, an), (b0, _b1, bn) in zip(used, used[1:]):
            if b0 < a1:
                raise self.err("table", f"{bn} at {b0} overlaps {an} ({a0}..{a1 - 1})")
        if used[-1][1] > 0x10000:
            raise self.err("table", "bank_base: the banks run past address 65535")
        return layout, ""
