"""One parser per kind of value a person types: a length in mm, a speed, a count, a temperature,
a seed, a port, ... Each kind has its unit, its bounds and its one-line refusal, and the command
line (argparse `type=`), the terminal UI's inputs and the config loader all call the same one, so
a string means the same thing wherever it is typed.

Rules every kind follows:
- The text is read whole: surrounding blanks are stripped, nothing else is dropped, reordered or
  guessed. A string that is not exactly a value of the kind is refused.
- **A decimal comma is refused, everywhere**, with a message saying to write a point: `1,5` could be
  one and a half (a European decimal) or fifteen (a thousands separator), and on a station that
  moves legs a guess is a crash; commas also separate list items (`--legs 1,4`). So `1,5` is
  refused as "write 1.5 with a decimal point", never read as 1.5 or 15.
- NaN and infinities are never values; bounds are inclusive unless a kind says otherwise.

`Kind.parse(text, where)` returns the value or raises InputError("<where>: '<text>' <why>; <what to
type>"). `Kind.argtype()` is the same parser for argparse (its refusal as an ArgumentTypeError, so
argparse prints `station CMD: error: argument --x: ...` and exits 2).

Kept free of heavy imports: `station X --help` and argument errors load only this.
"""

from __future__ import annotations

import argparse
import math
import re
from dataclasses import dataclass, replace
from typing import Any, Callable

from procedures.vocabulary import InputError

_FLOAT_RE = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
_INT_RE = re.compile(r"[+-]?\d+", re.ASCII)


def _num(value: float) -> str:
    if float(value).is_integer() and abs(value) < 1e15:
        return str(int(value))  # 4294967295, not 4.29497e+09
    return f"{value:.6g}"


@dataclass(frozen=True)
class Kind:
    """A kind of value: `name` (what it is, for messages), `unit` ('' when none), inclusive bounds
    `lo`/`hi` (None: unbounded on that side), `integer` for counts and numbers of things,
    `lo_open`/`hi_open` for strict bounds (a speed > 0), `words` for named values
    ('max' -> None), and `example` shown in refusals."""

    name: str
    unit: str = ""
    lo: float | None = None
    hi: float | None = None
    integer: bool = False
    lo_open: bool = False
    hi_open: bool = False
    words: tuple[tuple[str, Any], ...] = ()
    example: str = ""

    def bounded(self, lo: float | None = None, hi: float | None = None) -> "Kind":
        """The same kind within tighter bounds (a target within this leg's soft limits)."""
        return replace(self, lo=self.lo if lo is None else lo, hi=self.hi if hi is None else hi)

    def range_text(self) -> str:
        u = f" {self.unit}" if self.unit else ""
        if self.lo is not None and self.hi is not None:
            return f"{'>' if self.lo_open else ''}{_num(self.lo)} .. {_num(self.hi)}{u}"
        if self.lo is not None:
            return f"{'>' if self.lo_open else '>='} {_num(self.lo)}{u}"
        if self.hi is not None:
            return f"{'<' if self.hi_open else '<='} {_num(self.hi)}{u}"
        return f"any{u}"

    def _expect(self) -> str:
        what = "a whole number" if self.integer else "a number"
        extra = "".join(f" or '{w}'" for w, _ in self.words)
        example = f", e.g. {self.example}" if self.example else ""
        return f"give {self.name} as {what}{extra} ({self.range_text()}){example}"

    def parse(self, text: Any, where: str = "") -> Any:
        """`text` as a value of this kind, else InputError naming `where`, the text, why, and what
        to type. Numbers (int/float, not bool) are accepted as they are, then bounded."""
        prefix = f"{where}: " if where else ""
        if isinstance(text, bool) or text is None:
            raise InputError(f"{prefix}{text!r} is not a value; {self._expect()}")
        if isinstance(text, (int, float)):
            value = text
            shown = repr(text)
        else:
            s = str(text).strip()
            shown = repr(s)
            for word, meaning in self.words:
                if s.lower() == word:
                    return meaning
            if not s:
                raise InputError(f"{prefix}empty; {self._expect()}")
            if "," in s and _FLOAT_RE.fullmatch(s.replace(",", ".", 1)):
                fixed = s.replace(",", ".", 1)
                raise InputError(f"{prefix}{shown}: a comma is not a decimal separator here (it could mean "
                                 f"{fixed} or {s.replace(',', '')}); write {fixed} with a decimal point")
            pattern = _INT_RE if self.integer else _FLOAT_RE
            if not pattern.fullmatch(s):
                if self.integer and _FLOAT_RE.fullmatch(s):
                    raise InputError(f"{prefix}{shown} is not a whole number; {self._expect()}")
                raise InputError(f"{prefix}{shown} is not a number; {self._expect()}")
            try:
                value = int(s) if self.integer else float(s)
            except (ValueError, OverflowError):
                raise InputError(f"{prefix}{shown} is not a number; {self._expect()}") from None
        if self.integer and isinstance(value, float):
            if not value.is_integer():
                raise InputError(f"{prefix}{shown} is not a whole number; {self._expect()}")
            value = int(value)
        if not self.integer:
            value = float(value)
            if not math.isfinite(value):
                raise InputError(f"{prefix}{shown} is not a finite number; {self._expect()}")
        lo_bad = self.lo is not None and (value <= self.lo if self.lo_open else value < self.lo)
        hi_bad = self.hi is not None and (value >= self.hi if self.hi_open else value > self.hi)
        if lo_bad or hi_bad:
            raise InputError(f"{prefix}{shown} is outside {self.range_text()}; {self._expect()}")
        return value

    def argtype(self, option: str = "") -> Callable[[str], Any]:
        """This parser as an argparse `type=`: the refusal becomes an ArgumentTypeError (exit 2,
        one line). argparse names the option itself, so `option` is only used in the text when
        given explicitly."""
        def convert(text: str) -> Any:
            try:
                return self.parse(text, option)
            except InputError as exc:
                raise argparse.ArgumentTypeError(str(exc)) from None
        convert.__name__ = self.name.replace(" ", "_")  # argparse's "invalid <name> value" fallback
        convert.kind = self  # the CLI contract test (tests/station/test_cli_contract.py) bounds-checks by it
        return convert


# -- the kinds -------------------------------------------------------------------------------------
# Bounds are the widest that mean anything on this station; a use with tighter ones (a leg's soft
# limits, a plan's size limit) narrows them with Kind.bounded.

POSITION_MM = Kind("a position", "mm", -1000.0, 1000.0, example="12.5")
"""A leg position in mm from mid-stroke, + = extension. Narrow to the leg's soft limits before any
motion (Kind.bounded(lo, hi))."""

STEP_MM = Kind("a step", "mm", 0.0, 1000.0, lo_open=True, example="5")
"""A spacing or jog step in mm, > 0."""

SPEED_MM_S = Kind("a speed", "mm/s", 0.0, 1000.0, lo_open=True, example="20")
"""An axis speed in mm/s, > 0 (a leg moves at tens of mm/s; 1 m/s is a unit error)."""

TIME_S = Kind("a time", "s", 0.0, 86400.0, example="2.5")
"""A duration in seconds (a dwell, a timeout), 0 .. one day."""

TIME_SCALE = Kind("a time scale", "", 0.0, 1000.0, example="0.1")
"""The simulated rig's clock factor: 1 = real time, 0 = no waiting."""

SPEED_FACTOR = Kind("a speed factor", "", 0.0, 1e6, lo_open=True, words=(("max", None),), example="10")
"""A replay speed: 1 = real time, N = N times faster, 'max' (None) = as fast as possible."""

REPLAY_SPEED = Kind("a speed factor", "", 0.0, 1e6, lo_open=True,
                    words=(("max", None), ("fastest", None), ("inf", None)), example="10")
"""A replay's pace (`station replay --speed`, the Replay page): SPEED_FACTOR with the words the
replay has always taken for 'as fast as possible' (max, fastest, inf)."""

TEMP_C = Kind("a temperature", "degC", -50.0, 150.0, example="20")
AIR_TEMP_C = Kind("an air temperature", "degC", -10.0, 50.0, example="20")
PRESSURE_HPA = Kind("an air pressure", "hPa", 500.0, 1100.0, example="1013.25")
HUMIDITY_PCT = Kind("a relative humidity", "%RH", 0.0, 100.0, example="50")
LOAD_N = Kind("an axial load", "N", -100_000.0, 100_000.0, example="500")
ERROR_UM = Kind("an error", "um", -1000.0, 1000.0, example="3.5")
TOLERANCE_UM = Kind("a tolerance", "um", 0.0, 10_000.0, lo_open=True, example="5")
LEAD_MM = Kind("a screw lead", "mm", 0.0, 100.0, lo_open=True, example="5")

COUNT = Kind("a count", "", 1, 1_000_000, integer=True, example="5")
"""A number of things, >= 1. Narrow the upper bound to what the use can hold (Kind.bounded)."""

SEED = Kind("a seed", "", 0, 2**32 - 1, integer=True, example="0")
"""A random seed: numpy's generators take 0 .. 2**32 - 1."""

PORT = Kind("a TCP port", "", 1, 65535, integer=True, example="8080")
PORT_OR_ANY = Kind("a TCP port", "", 0, 65535, integer=True, example="5020")
"""0 lets the system pick a free port (the simulated rig prints the one it got)."""

LEG = Kind("a leg number", "", 1, 6, integer=True, example="3")

# -- numbers the command line and the config share ------------------------------------------------
# Upper bounds of counts are what a bench PC can hold and finish; the sizes that depend on the
# inputs (a plan's points, a platform run's memory) are estimated and refused further by the command.

CYCLES = Kind("a number of cycles", "", 1, 1000, integer=True, example="5")
"""Bidirectional cycles of a sweep plan (the plan's size is then checked against [limits])."""
TARGET_COUNT = Kind("a number of targets", "", 2, 1_000_000, integer=True, example="11")
POSES = Kind("a number of poses", "", 1, 100_000_000, integer=True, example="2000")
"""Random platform poses; `station platform` estimates memory and time and refuses beyond its limit."""
COSINE_TERMS = Kind("a number of cosine terms", "", 1, 100_000, integer=True, example="100")
"""The paper method's terms kept; the fit refuses more than the recording's targets give."""
SEEDS = Kind("a number of seeds", "", 1, 10_000, integer=True, example="20")
BANK_TYPE = Kind("a COMP_FILE_TYPE", "", 0, 1, integer=True, example="0")
OVERRUN_MM = Kind("an overrun", "mm", 0.0, 100.0, example="2")
HALF_RANGE_MM = Kind("a workspace half-range", "mm", 0.0, 1000.0, example="60")
TILT_DEG = Kind("a tilt half-range", "deg", 0.0, 90.0, example="3")
YAW_DEG = Kind("a yaw half-range", "deg", 0.0, 180.0, example="0")
THRESHOLD_UM = Kind("an effect threshold", "um", 0.0, 1000.0, example="0.1")
ALPHA = Kind("a significance level", "", 0.0, 0.5, lo_open=True, example="0.001")
CONTRIBUTION_UM = Kind("an RMS contribution", "um", 0.0, 1000.0, lo_open=True, example="1")
MOTOR_TURN_MM = Kind("a travel per motor turn", "mm", 0.0, 100.0, lo_open=True, example="2.5")
LEAD_OR_AUTO_MM = Kind("a screw lead", "mm", 0.0, 100.0, lo_open=True,
                       words=(("auto", "auto"), ("none", None)), example="5")
"""--lead-mm of fit and report: a lead in mm, 'auto' (look for it in the data) or 'none' (no
once-per-revolution terms). 0 is refused like -5: 'none' is the word for no lead."""
TEMP_OFFSET_K = Kind("an air temperature offset", "K", -20.0, 20.0, example="0.5")
PRESSURE_PA = Kind("an air pressure", "Pa", 50_000.0, 110_000.0, example="101325")
"""recorrect --pressure-pa; the same physical range as PRESSURE_HPA, in Pa."""

# [metrology] and [legs] of the config (station/services/config.py `_BOUNDS`) and the matching
# `station recorrect` options: one kind each, so a value means the same in both.
REFERENCE_TEMP_C = Kind("the reference temperature of lengths", "degC", -10.0, 50.0, example="20")
WAVELENGTH_NM = Kind("a vacuum wavelength", "nm", 400.0, 1700.0, example="632.991")
CO2_PPM = Kind("a CO2 content", "ppm", 0.0, 5000.0, example="450")
DEAD_PATH_MM = Kind("a dead path", "mm", 0.0, 10_000.0, example="100")
LASER_ACCURACY_PPM = Kind("a laser accuracy", "ppm", 0.0, 100.0, example="0.5")
LASER_RESOLUTION_NM = Kind("a laser resolution", "nm", 0.0, 10_000.0, example="1")
AIR_TEMP_U_C = Kind("a standard uncertainty of the air temperature", "K", 0.0, 10.0, example="0.1")
PRESSURE_U_PA = Kind("a standard uncertainty of the air pressure", "Pa", 0.0, 10_000.0, example="20")
HUMIDITY_U_PCT = Kind("a standard uncertainty of the humidity", "%RH", 0.0, 100.0, example="2")
MATERIAL_TEMP_U_C = Kind("a standard uncertainty of the material temperature", "K", 0.0, 10.0, example="0.1")
MISALIGNMENT_MM = Kind("a lateral beam offset", "mm", 0.0, 100.0, example="0.5")
ABBE_OFFSET_MM = Kind("an Abbe offset", "mm", 0.0, 1000.0, example="10")
ABBE_ANGLE_U_URAD = Kind("a standard uncertainty of the angular error", "urad", 0.0, 10_000.0, example="5")
EXPANSION_UM_M_K = Kind("an expansion coefficient", "um/m/K", 0.0, 50.0, example="11.5")
FIXED_POINT_MM = Kind("a fixed point", "mm", -5000.0, 5000.0, example="0")

__all__ = ["Kind", "TextKind", "PathKind", "CYCLES", "TARGET_COUNT", "POSES", "COSINE_TERMS", "SEEDS",
           "LEAD_OR_AUTO_MM", "DATE", "DATE_OR_TODAY", "LEGS", "LEG_CHOICE", "SERIAL", "LEG_SERIAL", "CATALOG",
           "IN_FILE", "IN_TEXT", "OUT_FILE", "OUT_DIR", "OUT_PATH", "IN_DIR", "LOG_FILE", "POSITION_MM", "STEP_MM", "SPEED_MM_S", "TIME_S", "TIME_SCALE", "SPEED_FACTOR",
           "TEMP_C", "AIR_TEMP_C", "PRESSURE_HPA", "HUMIDITY_PCT", "LOAD_N", "ERROR_UM", "TOLERANCE_UM",
           "LEAD_MM", "COUNT", "SEED", "PORT", "PORT_OR_ANY", "LEG"]


# -- values that are not numbers -------------------------------------------------------------------
# Same contract as Kind: parse(text, where) gives the value or raises InputError (one line: where,
# the text, why, what to type); argtype() is it for argparse. They return the text as typed (a
# path, a date, a leg list), so the command's run() reads exactly what was checked.

_CONTROL_RE = re.compile(r"[\x00-\x1f\x7f]")


def _argtype(kind: Any, option: str = "") -> Callable[[str], Any]:
    def convert(text: str) -> Any:
        try:
            return kind.parse(text, option)
        except InputError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    convert.__name__ = kind.name.replace(" ", "_")
    convert.kind = kind
    return convert


def _prefix(where: str) -> str:
    return f"{where}: " if where else ""


def _expanded(text: str, where: str, name: str):
    """`text` as a Path with ~ expanded; `~nobody-known/x` is refused (pathlib raises RuntimeError:
    found by tests/station/test_cli_contract.py's long profile with `--db ~0`)."""
    from pathlib import Path

    try:
        return Path(text).expanduser()
    except RuntimeError:
        raise InputError(f"{_prefix(where)}{text}: no user {text.split('/')[0][1:]!r} whose home folder '~' could "
                         f"name; give {name} as a full path") from None


@dataclass(frozen=True)
class TextKind:
    """A name or a label typed as text: 1..`max_len` printable characters (no control character,
    no leading/trailing blank kept), optionally matching `pattern` (described by `rule`), or one of
    `choices`. `check` is a further rule (a callable raising InputError), e.g. the serial grammar."""

    name: str
    max_len: int = 200
    pattern: str = ""
    rule: str = ""
    example: str = ""
    check: Callable[[str, str], Any] | None = None
    empty_ok: bool = False

    def parse(self, text: Any, where: str = "") -> str:
        prefix = _prefix(where)
        s = "" if text is None else str(text).strip()
        example = f", e.g. {self.example}" if self.example else ""
        if not s and self.empty_ok:
            return ""
        if not s:
            raise InputError(f"{prefix}empty; give {self.name}{example}")
        if _CONTROL_RE.search(s):
            raise InputError(f"{prefix}{s!r} holds a control character; give {self.name}{example}")
        if len(s) > self.max_len:
            raise InputError(f"{prefix}{len(s)} characters, more than {self.max_len}; give {self.name}{example}")
        if self.pattern and not re.fullmatch(self.pattern, s):
            raise InputError(f"{prefix}{s!r} is not {self.name} ({self.rule}){example}")
        if self.check is not None:
            result = self.check(s, where)
            return s if result is None else result
        return s

    def argtype(self, option: str = "") -> Callable[[str], Any]:
        return _argtype(self, option)


def _iso_date(text: str, where: str) -> str:
    import datetime as _dt

    try:
        if not re.fullmatch(r"\d{4}-\d{2}-\d{2}", text):
            raise ValueError(text)
        return _dt.date.fromisoformat(text).isoformat()
    except ValueError:
        raise InputError(f"{_prefix(where)}{text!r} is not a date; give it as YYYY-MM-DD, e.g. 2026-03-14") from None


DATE = TextKind("a date", max_len=10, check=_iso_date, example="2026-03-14")
"""A day, YYYY-MM-DD exactly (no time, no other order: 03/04/2026 is refused, never guessed)."""


def _date_or_today(text: str, where: str) -> str:
    return "today" if text.lower() == "today" else _iso_date(text, where)


DATE_OR_TODAY = TextKind("a date or 'today'", max_len=10, check=_date_or_today, example="2026-03-14")


def _date_time(text: str, where: str) -> str:
    import datetime as _dt

    try:
        if not re.fullmatch(r"\d{4}-\d{2}-\d{2}([T ]\d{2}:\d{2}(:\d{2}(\.\d+)?)?(Z|[+-]\d{2}:\d{2})?)?", text):
            raise ValueError(text)
        _dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise InputError(f"{_prefix(where)}{text!r} is not a date or time; give YYYY-MM-DD or "
                         "YYYY-MM-DDTHH:MM[:SS] (UTC), e.g. 2026-03-14T09:30") from None
    return text


DATE_TIME = TextKind("a date or date and time", max_len=35, check=_date_time, example="2026-03-14T09:30")
"""A day or a moment, ISO 8601 (a time without a zone is UTC); returned as typed, once checked."""


def _serial_or_leg_serial(text: str, where: str) -> str:
    return _leg_serial(text, where) if "=" in text else _serial(text, where)


def leg_numbers(text: str, where: str = "", all_word: bool = False, count: int = 6) -> tuple[int, ...]:
    """'3', '1-6', '1,4' (and 'all' when `all_word`) as leg numbers, in order, each once. Stricter
    than reading it loosely: a reversed range (4-2), an empty item (1,,2) and legs beyond `count`
    are refused, not dropped."""
    s = str(text).strip()
    what = f"give a leg number 1..{count}, a range (1-{count}), a list (1,4)" + (" or all" if all_word else "")
    if all_word and s.lower() == "all":
        return tuple(range(1, count + 1))
    legs: list[int] = []
    for part in s.split(","):
        part = part.strip()
        m = re.fullmatch(r"(\d{1,3})(?:\s*-\s*(\d{1,3}))?", part)
        if not m:
            raise InputError(f"{_prefix(where)}{s!r}: {part!r} is not a leg or a range; {what}")
        a = int(m.group(1))
        b = int(m.group(2)) if m.group(2) else a
        if b < a:
            raise InputError(f"{_prefix(where)}{s!r}: the range {part} runs backwards; {what}")
        if a < 1 or b > count:
            raise InputError(f"{_prefix(where)}{s!r}: leg numbers run from 1 to {count}; {what}")
        legs.extend(range(a, b + 1))
    return tuple(dict.fromkeys(legs))


def _legs(text: str, where: str) -> str:
    leg_numbers(text, where)
    return text


def _leg_choice(text: str, where: str) -> str:
    leg_numbers(text, where, all_word=True)
    return text


LEGS = TextKind("legs", max_len=40, check=_legs, example="1-6 or 1,3")
"""--legs: a leg, a range or a list (the command reads the same text with plans.parse_legs)."""
LEG_CHOICE = TextKind("legs", max_len=40, check=_leg_choice, example="2, 1-3, 1,4 or all")


def _serial(text: str, where: str) -> str:
    from station.services.serials import check_serial  # the one serial rule (kept light: re, csv)

    try:
        return check_serial(text, where)
    except InputError as exc:  # its message starts with `where: `; argparse names the option itself
        raise InputError(str(exc).removeprefix(": ")) from None


def _leg_serial(text: str, where: str) -> str:
    from station.services.serials import parse_serial_args  # the one LEG=SERIAL rule

    try:
        parse_serial_args([text])
    except InputError as exc:
        raise InputError(f"{_prefix(where)}{exc}") from None
    return text


SERIAL = TextKind("a serial number", max_len=64, check=_serial, example="HX-0042")
LEG_SERIAL = TextKind("LEG=SERIAL", max_len=80, check=_leg_serial, example="3=HX-0042")
SERIAL_OR_LEG_SERIAL = TextKind("SERIAL or LEG=SERIAL", max_len=80, check=_serial_or_leg_serial,
                                example="HX-0042 or 3=HX-0042")
NAME_TEXT = TextKind("a name", max_len=200, example="ACME Robotics")
"""A label stored or matched as typed (an operator, a customer, a leg type, a station id)."""
NAME_OR_EMPTY = TextKind("a name", max_len=200, example="ACME Robotics", empty_ok=True)
"""The same where empty means 'not stated' (an operator, a revision's reason left blank)."""
LEGS_AUDITED = TextKind("legs", max_len=40, example="2, 1-3, 1,4 or all")
"""push's --leg: only its characters checked here; the command reads it and audits a refusal."""
OP_ID = TextKind("an operation id", max_len=64, pattern=r"[0-9A-Za-z-]+", rule="the op column's characters",
                 example="3fa2c1d0")
REPORT_NO = TextKind("a report number", max_len=80, pattern=r"[0-9A-Za-z][0-9A-Za-z._/-]*",
                     rule="letters, digits, . _ / -", example="CAL-2026-0042")
WORD_LIST = TextKind("a comma-separated list of names", max_len=400, pattern=r"[A-Za-z0-9_]+(\s*,\s*[A-Za-z0-9_]+)*",
                     rule="names separated by commas", example="backlash,thermal")


# -- paths -----------------------------------------------------------------------------------------

_SQLITE_MAGIC = b"SQLite format 3\x00"


@dataclass(frozen=True)
class PathKind:
    """A path on the command line, checked before anything runs.

    role "in": an existing readable file (not a folder); `text`: not a binary file (no NUL byte
    and valid UTF-8 in its first 64 kB), as a CSV, TOML or JSON is; `max_bytes`: refused when
    bigger (sized first: a targets file of 2 GB is not read to find out).
    role "out": a file to write: not a folder; its folder exists and this user can write there
    (whether it exists already is the command's --force rule, procedures/io/outputs.py).
    role "dir_out": a folder to write (created by the command): not a file; its parent exists
    and can be written (nothing is created behind the user's back, as for a file).
    role "path_out": either ("TABLE.csv|DIR").
    role "log": a file appended to: a file if it exists, else its folder exists.
    role "in_dir": an existing readable folder.
    role "name": a file the command itself reads and refuses (push's table: its refusal goes to the
    audit log, so it must reach the command): only not empty and no control character here."""

    name: str
    role: str = "in"
    text: bool = False
    max_bytes: int | None = None
    example: str = ""
    not_this: tuple[tuple[bytes, str], ...] = ()
    """(a marker in the first lines, what the file is then): a file of another kind given for this
    one is named for what it is ("a table, not a model"), not reported as damaged."""

    def parse(self, text: Any, where: str = "") -> str:
        import os
        from pathlib import Path

        prefix = _prefix(where)
        s = "" if text is None else str(text)
        if not s.strip():
            raise InputError(f"{prefix}empty; give {self.name}" + (f", e.g. {self.example}" if self.example else ""))
        if _CONTROL_RE.search(s):  # a typed path never holds one: a paste or a slip, refused as typed
            raise InputError(f"{prefix}{s!r} holds a control character; give {self.name}")
        p = _expanded(s, where, self.name)
        if self.role == "name":
            return s
        try:
            if self.role in ("in", "in_dir"):
                return self._existing(p, s, prefix)
            if self.role == "log" and p.exists():
                if p.is_dir():
                    raise InputError(f"{prefix}{s} is a folder; give {self.name} (a file)")
                return s
            return self._writable(p, s, prefix)
        except OSError as exc:  # a name too long, a loop of links: the system's own words
            raise InputError(f"{prefix}{s}: {(exc.strerror or str(exc)).lower()}; give {self.name}") from None

    def _existing(self, p, s: str, prefix: str) -> str:
        import os

        if not p.exists():
            raise InputError(f"{prefix}{s}: no such {'folder' if self.role == 'in_dir' else 'file or directory'}; "
                             f"give {self.name}")
        if self.role == "in_dir":
            if not p.is_dir():
                raise InputError(f"{prefix}{s} is a file, not a folder; give {self.name}")
            if not os.access(p, os.R_OK | os.X_OK):
                raise InputError(f"{prefix}{s}: permission denied (this user cannot read the folder); "
                                 "fix its permissions or give another")
            return s
        if p.is_dir():
            raise InputError(f"{prefix}{s} is a folder, not a file; give {self.name}")
        if not p.is_file():
            raise InputError(f"{prefix}{s} is not a regular file; give {self.name}")
        size = p.stat().st_size
        if self.max_bytes is not None and size > self.max_bytes:
            raise InputError(f"{prefix}{s}: {size / 1e6:.1f} MB, more than any {self.name} holds (at most "
                             f"{self.max_bytes / 1e6:g} MB); give the right file")
        try:
            with open(p, "rb") as f:
                head = f.read(65536 if self.text or self.not_this else 0)
        except PermissionError:
            raise InputError(f"{prefix}{s}: permission denied (this user cannot read it); fix its permissions "
                             "or copy it somewhere readable") from None
        first_lines = b"\n".join(head.splitlines()[:3])
        for marker, what in self.not_this:
            if marker in first_lines:
                raise InputError(f"{prefix}{s} is {what}")
        if self.text:
            if b"\x00" in head:
                raise InputError(f"{prefix}{s} is a binary file, not text; give {self.name}")
            try:
                head.decode("utf-8")
            except UnicodeDecodeError as exc:
                if exc.start < len(head) - 4 or len(head) < 65536:  # not a character cut at the end
                    raise InputError(f"{prefix}{s} is not UTF-8 text (byte {exc.start}); give {self.name}") from None
        return s

    def _writable(self, p, s: str, prefix: str) -> str:
        import os
        from pathlib import Path

        if self.role == "out" and p.is_dir():
            raise InputError(f"{prefix}{s} is a folder; give a file name for {self.name}")
        if self.role == "dir_out" and p.exists() and not p.is_dir():
            raise InputError(f"{prefix}{s} is a file; give a folder for {self.name}")
        folder = p.parent
        if str(folder) == ".":  # "the folder ." tells nobody where: name it
            folder = Path(os.path.abspath(folder))
        if not folder.is_dir():
            what = "is a file, not a folder" if folder.exists() else "does not exist"
            raise InputError(f"{prefix}{s}: the folder {folder} {what}; create it first or choose another "
                             f"place; nothing was written")
        if not os.access(folder, os.W_OK | os.X_OK):
            raise InputError(f"{prefix}{s}: the folder {folder} cannot be written by this user (permission "
                             "denied); choose a folder you can write, or make it writable; nothing was written")
        return s

    def argtype(self, option: str = "") -> Callable[[str], Any]:
        return _argtype(self, option)


IN_FILE = PathKind("an input file")
SESSION = PathKind("a session file (FILE.h5)", example="runs/run.h5")
IN_TEXT = PathKind("a text file", text=True)
CONFIG = PathKind("a station config (TOML text)", text=True, max_bytes=10_000_000, example="station.toml")
PROFILE = PathKind("a drive profile (TOML text)", text=True, max_bytes=10_000_000)
TOML_FILE = PathKind("a TOML file", text=True, max_bytes=10_000_000)
MODEL = PathKind("a model file (MODEL.json from `station fit`)", text=True, max_bytes=200_000_000, not_this=(
    (b"position_mm", "a table CSV, not a model; give the MODEL.json `station fit` wrote (a table is pushed: "
                     "station push TABLE.csv --leg N)"),
    (b"\x89HDF", "a session file (HDF5), not a model; fit it first: station fit FILE.h5 --out model.json")))
TABLE = PathKind("a table CSV (from `station table`)", text=True, max_bytes=200_000_000)
TABLE_TO_PUSH = PathKind("a table CSV (from `station table`)", role="name")
AUDIT_TO_READ = PathKind("an audit log", role="name")
"""`station audit --audit`: read by the audit reader, which names a missing or damaged log itself."""
SESSION_TO_RESUME = PathKind("a session file (FILE.h5)", role="name")
"""`sweep --resume`: checked by check_appendable (exists, writable), after the arguments' conflicts."""
"""push's table: read by the push job, whose refusals (missing, cut, binary) are audited."""
CSV_IN = PathKind("a CSV file", text=True)
TARGETS_FILE = PathKind("a targets file (mm, one per line)", text=True, max_bytes=10_000_000)
"""Sized first: 10 MB holds about a million targets, twice the default [limits] max_points."""
SERIALS_FILE = PathKind("a serials file (CSV leg,serial,...)", text=True, max_bytes=1_000_000)
OUT_FILE = PathKind("an output file", role="out")
OUT_DIR = PathKind("an output folder", role="dir_out")
OUT_PATH = PathKind("an output file or folder", role="path_out")
LOG_FILE = PathKind("a log file", role="log")
IN_DIR = PathKind("a folder", role="in_dir")


def _catalog(text: str, where: str) -> str:
    """A database URL (sqlite:///FILE, postgresql://...) or an existing SQLite file."""
    prefix = _prefix(where)
    m = re.fullmatch(r"([a-z][a-z0-9+]*)://(.*)", text)
    if m:
        scheme = m.group(1)
        if scheme.split("+")[0] not in ("sqlite", "postgresql", "postgres"):
            raise InputError(f"{prefix}{text!r}: a catalog URL is sqlite:///FILE or postgresql://USER@HOST/DB, "
                             f"not {scheme}://")
        if any(c.isspace() for c in text):
            raise InputError(f"{prefix}{text!r}: a URL holds no blank")
        return text
    from pathlib import Path

    if not _expanded(text, where, "the catalog").exists():
        raise InputError(f"{prefix}{text}: no such file; `station catalog sync` creates and fills the local catalog "
                         "(or give the shared catalog's URL, postgresql://USER@HOST/DB)")
    PathKind("a catalog (a SQLite file or a database URL)").parse(text, where)

    with open(_expanded(text, where, "the catalog"), "rb") as f:
        head = f.read(16)
    if head != _SQLITE_MAGIC:
        raise InputError(f"{prefix}{text} is not a catalog (not an SQLite file); give the catalog's SQLite file "
                         "(runs/catalog.sqlite) or its URL (postgresql://USER@HOST/DB)")
    return text


CATALOG = TextKind("a catalog URL or SQLite file", max_len=2000, check=_catalog, example="runs/catalog.sqlite")


def _twin(text: str, where: str) -> str:
    if re.match(r"(sim|fleet):", text):
        return text
    return IN_FILE.parse(text, where)


TWIN = TextKind("a twin (MODEL.json, REFERENCE.h5, sim:CONFIG.toml, sim:default or fleet:TYPE)", max_len=4000,
                check=_twin)
AXIS_NAME = TextKind("an axis name", max_len=32, pattern=r"[A-Za-z][A-Za-z0-9_]*", rule="a letter, then letters, "
                     "digits or _", example="X")
DRIVE_URL = TextKind("a drive URL", max_len=500, pattern=r"[a-z]+://\S+|sim",
                     rule="tcp://HOST:PORT or rtu:///dev/ttyUSB0?baud=115200", example="tcp://192.168.1.10:502")
