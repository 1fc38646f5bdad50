"""Files that prove themselves: the integrity record of the files one station step writes for
another (issue 31, item 2).

A table CSV, a serials list (CSV) and a model (JSON) are written by one command and read by the
next, sometimes days later, after a copy over a network share or an edit in a spreadsheet. A file
cut short (a full disk, a copy interrupted) or edited by hand can still parse: a table cut mid-row
whose last field reads `1.` is a valid 3-point table. So the writer records what it wrote, and the
reader refuses what does not match it, naming what differs.

CSV files (table, serials list): one comment line, the first of the file,

    # integrity: table rows=181 sha256=<64 hex digits>

`rows` counts the data rows (not comments, the header or blank lines); `sha256` is the hash of
every other line of the file, in order, each ended by "\\n" (UTF-8, a leading byte-order mark
dropped). Line ends are normalised (`str.splitlines`) so a file whose CRLF or final newline
changed in a copy still proves itself: the reader parses exactly the lines the hash covers. A
`#` line is a comment to every CSV reader the station has (and to `pandas.read_csv(comment="#")`).

Model files (JSON, which has no comments): a top-level member

    "integrity": {"legs": 6, "sha256": "<64 hex digits>"}

`sha256` is the hash of the document without that member, as `json.dumps(doc, indent=2,
sort_keys=True, allow_nan=False)` writes it: a reader re-serialises what it parsed, so the check
does not depend on whitespace, only on content.

A file without a record (made by hand, or by a station from before the record) is read only when
it is complete by the reader's own rules (every row whole, ending with a line end; for a table also
even steps and the leg's stroke covered) and is then said to be *unverified*, in one warning line.
Controller exports (LinuxCNC COMP_FILEs, Siemens, HEIDENHAIN, TwinCAT, ecmc) carry no record: the
programs that read them do not allow one (LinuxCNC stops at the first line that is not three
numbers) and the station never reads them back.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from procedures.vocabulary import InputError

RECORD_PREFIX = "# integrity:"
_RECORD_RE = re.compile(r"# integrity: (?P<kind>[a-z][a-z-]*) rows=(?P<rows>[0-9]{1,9}) sha256=(?P<sha>[0-9a-f]{64})")
MODEL_KEY = "integrity"

VERIFIED = "verified"
UNVERIFIED = "unverified"


class IntegrityError(InputError):
    """A file does not match its integrity record, or its record is malformed (the message names
    the file, what the record says, what the file holds, and what to do)."""


def _short(sha: str) -> str:
    return sha[:16]


def lines_sha256(lines: Sequence[str]) -> str:
    """The hash of `lines`, each ended by "\\n", as UTF-8."""
    h = hashlib.sha256()
    for line in lines:
        h.update(line.encode("utf-8", "surrogatepass"))
        h.update(b"\n")
    return h.hexdigest()


def csv_record_line(kind: str, body_lines: Sequence[str], rows: int) -> str:
    """The record line of a CSV whose lines after it are `body_lines`, holding `rows` data rows."""
    return f"{RECORD_PREFIX} {kind} rows={rows} sha256={lines_sha256(body_lines)}"


def with_csv_record(kind: str, text: str, rows: int) -> str:
    """`text` (the file's content, lines ended by "\\n") with its record line first."""
    body = text.splitlines()
    return csv_record_line(kind, body, rows) + "\n" + text


@dataclass(frozen=True)
class CsvRecord:
    """A CSV's record as read: its kind, rows and hash, and its line (1-based)."""

    kind: str
    rows: int
    sha256: str
    line: int


def _looks_like_record(line: str) -> bool:
    """A comment line meant as a record, even damaged (so an edit of the record itself is never
    taken for a file without one): it starts like one or holds one of its fields."""
    s = line.strip()
    return s.startswith("#") and ("integrity" in s.lower() or "sha256=" in s or "rows=" in s)


def split_csv_record(path: Path, lines: list[str], kind: str, remake: str) -> tuple[CsvRecord | None, list[str]]:
    """(the record, the other lines) of a CSV's `lines`; (None, lines) when it has none. Only
    the comment lines before the first other line are searched. IntegrityError when a record
    line is malformed, or is another kind's (`kind` expected; `remake` says how to make the
    file again)."""
    for i, line in enumerate(lines):
        if not line.lstrip().startswith("#"):
            break
        if _looks_like_record(line):
            m = _RECORD_RE.fullmatch(line.strip())
            if m is None:
                raise IntegrityError(
                    f"{path}, row {i + 1}: the integrity record {line.strip()[:100]!r} is damaged (expected "
                    f"'{RECORD_PREFIX} {kind} rows=N sha256=<64 hex>'): the file was edited or corrupted; {remake}")
            if m["kind"] != kind:
                raise IntegrityError(f"{path}, row {i + 1}: this is a {m['kind']} file (its integrity record says so), "
                                     f"not a {kind} file; {remake}")
            return CsvRecord(m["kind"], int(m["rows"]), m["sha"], i + 1), lines[:i] + lines[i + 1:]
    return None, lines


def check_csv_record(path: Path, record: CsvRecord, body: Sequence[str], rows_found: int, what: str,
                     remake: str) -> None:
    """IntegrityError naming what differs when `body` (the lines but the record's) with
    `rows_found` data rows does not match `record`. `what` names the rows ("table rows")."""
    sha = lines_sha256(body)
    if sha == record.sha256 and rows_found == record.rows:
        return
    if rows_found < record.rows:
        how = f"cut short: {record.rows - rows_found} row(s) missing"
    elif rows_found > record.rows:
        how = f"{rows_found - record.rows} row(s) added"
    else:
        how = "edited: same row count, different content"
    raise IntegrityError(
        f"{path}: does not match its integrity record (row {record.line}): the record says {record.rows} {what}, "
        f"sha256 {_short(record.sha256)}..., the file has {rows_found} {what}, sha256 {_short(sha)}... ({how}); "
        f"{remake}")


def last_line_whole(path: Path, text: str, what: str) -> None:
    """IntegrityError when a file without a record does not end with a line end: its last row may
    be cut mid-field (`1.` of `1.2345` still reads as a number)."""
    stripped = text.rstrip(" \t")
    if stripped and not stripped.endswith(("\n", "\r")):
        n = len(text.splitlines())
        raise IntegrityError(
            f"{path}, row {n}: the last row has no line end, so it may be cut mid-field, and the file has no "
            f"integrity record to tell; if the row is whole, end it with a line break; else {what}")


def unverified_line(path: str | Path, kind: str, checked: str) -> str:
    """The one warning line for a file read without a record."""
    return (f"warning: {path} has no integrity record (made by hand, or before the station wrote one): {kind} "
            f"accepted as complete ({checked}) but unverified")


# -- JSON ------------------------------------------------------------------------------------------

def json_body_sha256(doc: dict[str, Any]) -> str:
    """The hash of a JSON document without its record, serialised as the writers do."""
    body = {k: v for k, v in doc.items() if k != MODEL_KEY}
    text = json.dumps(body, indent=2, sort_keys=True, allow_nan=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def json_record(doc: dict[str, Any], count_key: str, count: int) -> dict[str, Any]:
    return {count_key: count, "sha256": json_body_sha256(doc)}


def check_json_record(path: Path, doc: dict[str, Any], count_key: str, count: int, remake: str) -> str:
    """VERIFIED when `doc`'s record matches it, UNVERIFIED when it has none; IntegrityError
    naming what differs otherwise."""
    if MODEL_KEY not in doc:
        return UNVERIFIED
    rec = doc[MODEL_KEY]
    if not (isinstance(rec, dict) and isinstance(rec.get("sha256"), str) and re.fullmatch(r"[0-9a-f]{64}", rec["sha256"])
            and isinstance(rec.get(count_key), int) and not isinstance(rec.get(count_key), bool)):
        raise IntegrityError(f"{path}: its integrity record ({MODEL_KEY!r}) is damaged (expected "
                             f"{{\"{count_key}\": N, \"sha256\": \"<64 hex>\"}}): the file was edited or corrupted; "
                             f"{remake}")
    try:
        sha = json_body_sha256(doc)
    except ValueError:  # a non-finite number written into it by hand
        sha = "(not serialisable)"
    if sha == rec["sha256"] and count == rec[count_key]:
        return VERIFIED
    how = "edited" if count == rec[count_key] else f"{count_key} {'missing' if count < rec[count_key] else 'added'}"
    raise IntegrityError(
        f"{path}: does not match its integrity record: the record says {rec[count_key]} {count_key}, sha256 "
        f"{_short(rec['sha256'])}..., the file has {count} {count_key}, sha256 {_short(sha)}... ({how} after it was written); "
        f"{remake}")


# -- what a file is, for readers given the wrong kind --------------------------------------------------

_KINDS = {  # key: (short name, what it is)
    "table": ("a table", "a compensation table CSV, as `station table` writes"),
    "serials": ("a serials list", "a CSV leg,serial,..."),
    "model": ("a model", "a leg-error model JSON, as `station fit` writes"),
    "session": ("a session", "a session file, HDF5"),
    "points": ("a points CSV", "an interchange CSV of points, as `station export` writes"),
    "linuxcnc": ("a LinuxCNC COMP_FILE", "three numbers a line, for LinuxCNC"),
    "config": ("a config", "a station config, TOML"),
    "json": ("another JSON file", "JSON, but not a file the station writes"),
    "image": ("an image", "PNG or JPEG"),
    "pdf": ("a PDF document", "PDF"),
}


def file_kind(path: str | Path, limit: int = 4096) -> str | None:
    """What `path` is, from its first bytes: a key of the readable names above (see `kind_name`),
    or None when it is none of them (or cannot be read)."""
    try:
        with open(path, "rb") as f:
            head = f.read(limit)
    except OSError:
        return None
    if head.startswith(b"\x89HDF\r\n\x1a\n"):
        return "session"
    if head.startswith(b"\x89PNG") or head.startswith(b"\xff\xd8\xff"):
        return "image"
    if head.startswith(b"%PDF"):
        return "pdf"
    try:
        text = head.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = head[: max(0, len(head) - 3)].decode("utf-8", "ignore")  # the limit may cut a character
    s = text.lstrip()
    if s.startswith("{"):
        return "model" if re.search(r'"format"\s*:\s*"station-leg-error-model"', text) else "json"
    m = _RECORD_RE.match(s)
    if m is not None:
        return m["kind"] if m["kind"] in _KINDS else None
    lines = [line.strip() for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        return None
    first = [c.strip().lower() for c in lines[0].split(",")]
    if first[:2] == ["leg", "position_mm"]:
        return "table"
    if first[:2] == ["leg", "serial"] or (first and first[0] == "leg" and "serial" in first):
        return "serials"
    if {"leg", "target_mm", "error_um"} <= set(first):
        return "points"
    if lines[0].startswith("[") and lines[0].endswith("]"):
        return "config"
    if all(len(line.split()) == 3 and all(_is_number(t) for t in line.split()) for line in lines[:3]):
        return "linuxcnc"
    return None


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def kind_name(kind: str) -> str:
    return _KINDS[kind][0] if kind in _KINDS else kind


def wrong_kind(path: str | Path, expected: str, hint: str) -> str | None:
    """"PATH: this is <what it is>, not <expected> (<what it is, in full>); <hint>" when `path` is
    a known other kind of file, else None (the caller then says what is wrong with it as its kind)."""
    kind = file_kind(path)
    if kind is None or kind == expected:
        return None
    return f"{path}: this is {kind_name(kind)}, not {kind_name(expected)} ({_KINDS[kind][1]}); {hint}"
