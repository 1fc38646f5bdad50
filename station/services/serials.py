"""Leg serial numbers entered for a session: `--serial 3=HX-0042`, a serials file, [legs.N].

Which wins (most specific last): the config's `[legs.N] serial/part_number/leg_type/screw_lot`,
then the serials file (`[station] serials_file` or `--serials FILE`), then `--serial N=SERIAL`
(or the Sweep page's fields). A serials file is CSV with a header:

    leg,serial,part_number,leg_type,screw_lot
    3,HX-0042,HX-L-300,HX300,L2026-11

`leg` and `serial` are required columns; the others optional (empty = not stated). A bad row is
refused naming the file, row and field, and nothing is recorded.

Comment lines (`#`) may come before the header. A serials list the station writes
(`write_serials_file`) starts with its integrity record, `# integrity: serials rows=N sha256=...`
(procedures/io/integrity.py): a list whose record does not match (cut, edited) is refused naming
what differs. One without a record (typed by hand) is read when its last row ends with a line end
(a serial cut mid-way is still a valid serial), and is said to be unverified
(`serials_unverified_line`, printed by `station sweep`).
"""

from __future__ import annotations

import csv
import re
from pathlib import Path
from typing import Iterable, Mapping

from procedures.vocabulary import InputError
from procedures.io.atomic_outputs import write_text_atomic
from procedures.io.integrity import (
    UNVERIFIED,
    VERIFIED,
    check_csv_record,
    last_line_whole,
    split_csv_record,
    unverified_line,
    with_csv_record,
    wrong_kind,
)

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


INTEGRITY_KIND = "serials"
REMAKE = ("write the list again (a header leg,serial[,part_number,leg_type,screw_lot], then a row per leg) or "
          "restore it from where it came")
_NOT_SERIALS = "give the serials CSV (header leg,serial[,part_number,leg_type,screw_lot]), e.g. --serials serials.csv"


def serials_file_text(legs: Mapping[int, Mapping[str, str]]) -> str:
    """A serials list of `legs` ({leg: {"serial", ...}}), its integrity record first; the columns
    are those any leg states. InputError for a serial or field `read_serials_file` would refuse."""
    cols = ["leg", "serial"] + [c for c in FILE_COLUMNS[2:] if any(v.get(c) for v in legs.values())]
    lines = [",".join(cols)]
    for leg in sorted(legs):
        rec = legs[leg]
        _leg(str(leg), f"leg {leg}")
        check_serial(rec.get("serial", ""), f"leg {leg}")
        for key in cols[2:]:
            if rec.get(key) and not (TEXT_RE.fullmatch(rec[key]) and "," not in rec[key] and '"' not in rec[key]):
                raise InputError(f"leg {leg}, field {key}: {rec[key]!r} is not 1..64 printable characters without , or \"")
        lines.append(",".join([str(leg)] + [rec.get(c, "") or "" for c in cols[1:]]))
    return with_csv_record(INTEGRITY_KIND, "\n".join(lines) + "\n", len(lines) - 1)


def write_serials_file(path: str | Path, legs: Mapping[int, Mapping[str, str]]) -> Path:
    """Write a serials list (`serials_file_text`) atomically: nothing half-written."""
    return write_text_atomic(Path(path), serials_file_text(legs))


def read_serials_file(path: str | Path) -> dict[int, dict[str, str]]:
    """The serials CSV (module docstring) -> {leg: {"serial", "part_number", ...}} (empty fields
    left out). InputError naming file, row and field for anything wrong."""
    return read_serials_file_checked(path)[0]


def serials_unverified_line(path: str | Path | None) -> str | None:
    """The one warning line for a serials list without an integrity record (None when it has a
    matching one, or no list is given). The list is read again: call it after it was accepted."""
    if not path:
        return None
    legs, integrity = read_serials_file_checked(path)
    if integrity != UNVERIFIED:
        return None
    return unverified_line(path, "serials list", f"legs {', '.join(map(str, legs)) or 'none'}, every row whole")


def read_serials_file_checked(path: str | Path) -> tuple[dict[int, dict[str, str]], str]:
    """`read_serials_file`, and "verified" or "unverified" (procedures/io/integrity.py)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputError(f"{p}: serials file not found") from None
    except UnicodeDecodeError as exc:
        raise InputError(wrong_kind(p, INTEGRITY_KIND, _NOT_SERIALS) or
                         f"{p}: not a UTF-8 text file (byte {exc.start}); a serials file is CSV text") from None
    except OSError as exc:
        raise InputError(f"{p}: cannot read the serials file ({exc.strerror or exc})") from None
    lines = text.splitlines()
    record, body = split_csv_record(p, lines, INTEGRITY_KIND, REMAKE)
    head = next((i for i, line in enumerate(lines) if not line.lstrip().startswith("#")), len(lines))
    if record is None:
        integrity = UNVERIFIED
        last_line_whole(p, text, REMAKE)
    else:
        integrity = VERIFIED
        b = next((i for i, line in enumerate(body) if not line.lstrip().startswith("#")), len(body))
        check_csv_record(p, record, body, sum(1 for x in body[b + 1:] if x.strip()), "serials rows", REMAKE)
    rows = list(csv.reader(lines[head:]))
    if not rows:
        raise InputError(f"{p}: empty; a serials file starts with the header {','.join(FILE_COLUMNS)}")
    header = [h.strip() for h in rows[0]]
    unknown = [h for h in header if h not in FILE_COLUMNS]
    if unknown or "leg" not in header or "serial" not in header or len(set(header)) != len(header):
        raise InputError(wrong_kind(p, INTEGRITY_KIND, _NOT_SERIALS) or
                         f"{p}: row {head + 1} (header): columns must be leg,serial and optionally part_number, "
                         f"leg_type, screw_lot, each once; got {','.join(header)}")
    out: dict[int, dict[str, str]] = {}
    for n, row in enumerate(rows[1:], start=head + 2):
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
    return out, integrity


def merged_leg_identity(config: Mapping[int, Mapping[str, str]], *more: Mapping[int, Mapping[str, str]]
                        ) -> dict[int, dict[str, str]]:
    """The legs' identity fields, later sources overriding earlier ones field by field."""
    out = {int(leg): dict(v) for leg, v in config.items()}
    for source in more:
        for leg, values in source.items():
            out.setdefault(int(leg), {}).update({k: v for k, v in values.items() if v})
    return out
