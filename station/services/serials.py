"""Leg serial numbers entered for a session: `--serial 3=HX-0042`, a serials file, [legs.N].

Which wins (most specific last): the config's `[legs.N] serial/part_number/leg_type/screw_lot`,
then the serials file (`[station] serials_file` or `--serials FILE`), then `--serial N=SERIAL`
(or the Sweep page's fields). A serials file is CSV with a header:

    leg,serial,part_number,leg_type,screw_lot
    3,HX-0042,HX-L-300,HX300,L2026-11

`leg` and `serial` are required columns; the others optional (empty = not stated). A bad row is
refused naming the file, row and field, and nothing is recorded.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path
from typing import Iterable, Mapping

from procedures.engine.errors import InputError

LEG_COUNT = 6
# The one serial grammar (sweep --serial, serials files, [legs.N], the TUI, history/certificate/
# compare, the web view's URLs): no '/' so a serial is one URL path segment and names one file
# part, and the first character a letter or digit so no serial is '.', '..' or a hidden name. A
# serial like "A/../HX-0042" would otherwise be a link a browser resolves to another leg's page.
SERIAL_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
SERIAL_RULE = "1..64 letters, digits, '.', '_' or '-', starting with a letter or digit (e.g. HX-0042)"
FILE_COLUMNS = ("leg", "serial", "part_number", "leg_type", "screw_lot")
TEXT_RE = re.compile(r"[^\x00-\x1f\x7f]{1,64}")


def check_serial(text: str, where: str) -> str:
    """`text` if it is a serial number (SERIAL_RULE), else InputError naming `where`."""
    if not is_serial(text):
        raise InputError(f"{where}: serial {text!r} is not a serial number: {SERIAL_RULE}"
                         + ("; '/' is not allowed (a serial is one segment of the web view's URLs)"
                            if isinstance(text, str) and "/" in text else ""))
    return text


def is_serial(text: object) -> bool:
    """Whether `text` follows the serial grammar (SERIAL_RULE)."""
    return isinstance(text, str) and SERIAL_RE.fullmatch(text) is not None


def _leg(text: str, where: str) -> int:
    t = str(text).strip()
    if not (t.isdigit() and 1 <= int(t) <= LEG_COUNT):
        raise InputError(f"{where}: leg {text!r} is not a leg number 1..{LEG_COUNT}")
    return int(t)


def parse_serial_args(values: Iterable[str]) -> dict[int, dict[str, str]]:
    """`--serial 3=HX-0042` (repeatable) -> {3: {"serial": "HX-0042"}}; a leg given twice with
    two serials is refused."""
    out: dict[int, dict[str, str]] = {}
    for value in values or ():
        leg_text, sep, serial = str(value).partition("=")
        where = f"--serial {value}"
        if not sep:
            raise InputError(f"{where}: write LEG=SERIAL, e.g. --serial 3=HX-0042")
        leg = _leg(leg_text, where)
        check_serial(serial.strip(), where)
        if leg in out and out[leg]["serial"] != serial.strip():
            raise InputError(f"{where}: leg {leg} already has serial {out[leg]['serial']}; give each leg once")
        out[leg] = {"serial": serial.strip()}
    return out


def read_serials_file(path: str | Path) -> dict[int, dict[str, str]]:
    """The serials CSV (module docstring) -> {leg: {"serial", "part_number", ...}} (empty fields
    left out). InputError naming file, row and field for anything wrong."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputError(f"{p}: serials file not found") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{p}: not a UTF-8 text file (byte {exc.start}); a serials file is CSV text") from None
    except OSError as exc:
        raise InputError(f"{p}: cannot read the serials file ({exc.strerror or exc})") from None
    rows = list(csv.reader(text.splitlines()))
    if not rows:
        raise InputError(f"{p}: empty; a serials file starts with the header {','.join(FILE_COLUMNS)}")
    header = [h.strip() for h in rows[0]]
    unknown = [h for h in header if h not in FILE_COLUMNS]
    if unknown or "leg" not in header or "serial" not in header or len(set(header)) != len(header):
        raise InputError(f"{p}: row 1 (header): columns must be leg,serial and optionally part_number, leg_type, "
                         f"screw_lot, each once; got {','.join(header)}")
    out: dict[int, dict[str, str]] = {}
    for n, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise InputError(f"{p}: row {n}: {len(row)} fields, the header has {len(header)}")
        rec = {h: c.strip() for h, c in zip(header, row)}
        leg = _leg(rec["leg"], f"{p}: row {n}, field leg")
        check_serial(rec["serial"], f"{p}: row {n}, field serial")
        for key in FILE_COLUMNS[2:]:
            if rec.get(key) and not TEXT_RE.fullmatch(rec[key]):
                raise InputError(f"{p}: row {n}, field {key}: {rec[key]!r} is not 1..64 printable characters")
        if leg in out:
            raise InputError(f"{p}: row {n}, field leg: leg {leg} is listed twice; give each leg once")
        out[leg] = {k: v for k, v in rec.items() if k != "leg" and v}
    return out


def merged_leg_identity(config: Mapping[int, Mapping[str, str]], *more: Mapping[int, Mapping[str, str]]
                        ) -> dict[int, dict[str, str]]:
    """The legs' identity fields, later sources overriding earlier ones field by field."""
    out = {int(leg): dict(v) for leg, v in config.items()}
    for source in more:
        for leg, values in source.items():
            out.setdefault(int(leg), {}).update({k: v for k, v in values.items() if v})
    return out
