"""One way to read a finite number from a file, a field or a config value, naming the place.

`parse_finite(value, where)` gives the float, or raises the caller's error (an InputError by
default) as `"<where>: '<value>' is not a number"` or `"... is not a finite number"` (NaN, inf):
the readers of tables, controller files, import maps, plans and the command line all word it
alike. `finite_float` is the same check for callers that word the refusal themselves.
"""

from __future__ import annotations

import math
from typing import Any

from procedures.vocabulary import InputError


class NotANumber(ValueError):
    """`value` is not a number (`parsed` is None) or not a finite one (`parsed` is the NaN or inf)."""

    def __init__(self, value: Any, parsed: float | None):
        self.value, self.parsed = value, parsed
        super().__init__(f"{value!r} is not a number" if parsed is None else f"{value!r} is not a finite number")


def finite_float(value: Any, *, text_ok: bool = True, decimal_comma: bool = False) -> float:
    """`value` (text when `text_ok`, an int or a float; never a bool) as a finite float, else
    NotANumber. `decimal_comma`: "1,5" reads as 1.5."""
    if isinstance(value, bool) or (isinstance(value, str) and not text_ok):
        raise NotANumber(value, None)
    try:
        v = float(value.replace(",", ".") if decimal_comma and isinstance(value, str) else value)
    except (TypeError, ValueError, OverflowError):
        raise NotANumber(value, None) from None
    if not math.isfinite(v):
        raise NotANumber(value, v)
    return v


def parse_finite(value: Any, where: str, error: type[Exception] = InputError, *, hint: str = "",
                 decimal_comma: bool = False, sep: str = ": ") -> float:
    """`value` as a finite float, else `error("<where>: <value!r> is not a number<hint>")` (or
    "is not a finite number" for NaN and inf). `hint` says what was expected (" (mm expected)");
    `sep` joins the place and the value ("target 'x'" reads better with " ")."""
    try:
        return finite_float(value, decimal_comma=decimal_comma)
    except NotANumber as exc:
        raise error(f"{where}{sep}{exc}{hint if exc.parsed is None else ''}") from None
