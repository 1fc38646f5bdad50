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

from procedures.engine.errors import InputError

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

__all__ = ["Kind", "POSITION_MM", "STEP_MM", "SPEED_MM_S", "TIME_S", "TIME_SCALE", "SPEED_FACTOR",
           "TEMP_C", "AIR_TEMP_C", "PRESSURE_HPA", "HUMIDITY_PCT", "LOAD_N", "ERROR_UM", "TOLERANCE_UM",
           "LEAD_MM", "COUNT", "SEED", "PORT", "PORT_OR_ANY", "LEG"]
