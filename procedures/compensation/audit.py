"""The audit log: an append-only JSON-lines record of every push, verify and rollback.

One line per entry, never rewritten: each append opens the file with O_APPEND under an exclusive
lock, writes one complete line and fsyncs it before returning, so an entry the caller was told
about survives a power cut. A push writes two entries: `outcome="started"` (with the backup of
the drive's previous table, before anything is written to the drive) and the final one (`ok`,
`failed`, `refused`, `cancelled`), linked by `op_id`. Rollback finds its backup here.

Entry fields (JSON keys; absent values are null):

    v             format version (1)
    id            unique id of the entry
    op_id         id shared by the entries of one operation (started + final)
    time_utc      "YYYY-MM-DDTHH:MM:SS.ffffffZ"
    operator      who (station config `operator`, default the login name)
    host          the computer's name
    action        "push" | "verify" | "rollback"
    leg           leg number
    drive         drive identity as it reports it ("vendor product s/n SERIAL fw FIRMWARE")
    drive_url     how it was reached (tcp://..., rtu://..., sim)
    outcome       "started" | "ok" | "failed" | "refused" | "cancelled" (push/rollback);
                  "completed" | "aborted" | "failed" (verify)
    message       one sentence: what happened
    table_sha256  the table written (push/rollback) or active (verify), see procedures.compensation.push.table_sha256
    bank          bank written / activated (push, rollback), or active (verify)
    previous_bank bank active before
    backup        the drive's previously active table, entries in full (push/rollback):
                  {"bank", "start_mm", "spacing_mm", "error_fwd_um": [...], "error_rev_um": [...],
                   "checksum", "sha256"}
    source        where the table came from, e.g. {"path": "table.csv", "sha256": "..."}
    details       action-specific figures (verify: RMS, noise floor, ISO 230-2 values, session)
    leg_serial    the serial the leg carries (station config [legs.N] serial); null when not configured
    station_id    the station that wrote the entry ([station] id, default the host name)

A line that is not a JSON object (e.g. cut short by a crash while being written) is reported by
`read_entries` as a problem and otherwise skipped; the next append starts on a new line.

Procedures never write here themselves: they yield `AuditRecord` events, and `AuditSink` (a
critical runner sink) is the only writer, for the command line and the terminal UI alike.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import uuid
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterable

from procedures.engine import events as ev
from procedures.engine.errors import InputError
from procedures.engine.states import Action, AuditOutcome

AUDIT_VERSION = 1
ACTIONS = tuple(Action)


class AuditError(InputError):
    """The audit log cannot be written or read (the message names the file and the problem)."""


def utc_now() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def new_id() -> str:
    return uuid.uuid4().hex[:16]


@dataclass(frozen=True)
class AuditEntry:
    """One line of the audit log (see the module docstring for the fields)."""

    action: str
    leg: int
    outcome: str
    message: str = ""
    drive: str = ""
    drive_url: str = ""
    operator: str = ""
    table_sha256: str = ""
    bank: int | None = None
    previous_bank: int | None = None
    backup: dict[str, Any] | None = None
    source: dict[str, Any] | None = None
    details: dict[str, Any] = field(default_factory=dict)
    op_id: str = ""
    id: str = ""
    time_utc: str = ""
    host: str = ""
    v: int = AUDIT_VERSION
    leg_serial: str | None = None
    station_id: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "v": self.v, "id": self.id, "op_id": self.op_id, "time_utc": self.time_utc,
            "operator": self.operator, "host": self.host, "action": self.action, "leg": self.leg,
            "drive": self.drive, "drive_url": self.drive_url, "outcome": self.outcome,
            "message": self.message, "table_sha256": self.table_sha256, "bank": self.bank,
            "previous_bank": self.previous_bank, "backup": self.backup, "source": self.source,
            "details": self.details, "leg_serial": self.leg_serial, "station_id": self.station_id,
        }

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> "AuditEntry":
        """An entry from a parsed line; ValueError when a required field is missing or mistyped."""
        if not isinstance(d, dict):
            raise ValueError("not a JSON object")
        for key, kind in (("action", str), ("leg", int), ("outcome", str)):
            if not isinstance(d.get(key), kind) or isinstance(d.get(key), bool):
                raise ValueError(f"field {key!r} missing or not a {kind.__name__}")
        return cls(
            action=d["action"], leg=d["leg"], outcome=d["outcome"], message=str(d.get("message") or ""),
            drive=str(d.get("drive") or ""), drive_url=str(d.get("drive_url") or ""),
            operator=str(d.get("operator") or ""), table_sha256=str(d.get("table_sha256") or ""),
            bank=d.get("bank"), previous_bank=d.get("previous_bank"), backup=d.get("backup"),
            source=d.get("source"), details=dict(d.get("details") or {}), op_id=str(d.get("op_id") or ""),
            id=str(d.get("id") or ""), time_utc=str(d.get("time_utc") or ""), host=str(d.get("host") or ""),
            v=int(d.get("v") or AUDIT_VERSION),
            leg_serial=d.get("leg_serial") if isinstance(d.get("leg_serial"), str) else None,
            station_id=d.get("station_id") if isinstance(d.get("station_id"), str) else None,
        )


@dataclass(frozen=True)
class AuditRecord(ev.Event):
    """An entry for the audit log (an AuditEntry). Procedures yield these; the
    audit sink (AuditSink) is the only writer of the log."""

    entry: AuditEntry


@dataclass(frozen=True)
class AuditProblem:
    """A line of the log that could not be read as an entry."""

    line: int
    reason: str


class AuditLog:
    """The append-only audit log at `path` (created with its directory on the first append).

    `operator`, `station_id` and `leg_serials` (leg -> serial) fill entries that do not name them. Thread- and process-safe appends (exclusive
    `flock` around each write).
    """

    def __init__(self, path: str | os.PathLike, operator: str = "", station_id: str | None = None,
                 leg_serials: dict[int, str] | None = None):
        self.path = Path(path)
        self.operator = operator
        self.station_id = station_id  # fills entries that name none
        self.leg_serials = dict(leg_serials or {})  # leg -> serial, fills entries that name none

    def __repr__(self) -> str:
        return f"AuditLog({str(self.path)!r})"

    # -- writing ----------------------------------------------------------------------------------
    def append(self, entry: AuditEntry) -> AuditEntry:
        """Append `entry` (id, time, host and operator filled in when empty) and fsync it.

        Returns the entry as written. AuditError (naming the file) if it cannot be written.
        """
        if entry.action not in ACTIONS:
            raise ValueError(f"unknown audit action {entry.action!r}")
        full = AuditEntry(**{**entry.__dict__,
                             "id": entry.id or new_id(),
                             "time_utc": entry.time_utc or utc_now(),
                             "host": entry.host or socket.gethostname(),
                             "operator": entry.operator or self.operator,
                             "station_id": entry.station_id or self.station_id,
                             "leg_serial": entry.leg_serial or self.leg_serials.get(entry.leg)})
        line = json.dumps(full.to_json(), sort_keys=True, separators=(",", ":"), allow_nan=False) + "\n"
        data = line.encode("utf-8")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        except OSError as exc:
            raise AuditError(f"audit log {self.path}: cannot open it for appending ({exc.strerror or exc}); "
                             "choose another file with --audit") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            size = os.fstat(fd).st_size
            if size:
                # a line cut short by a crash must not swallow this entry: start on a new line
                with open(self.path, "rb") as fh:
                    fh.seek(size - 1)
                    if fh.read(1) != b"\n":
                        data = b"\n" + data
            view = memoryview(data)
            while view:
                n = os.write(fd, view)
                view = view[n:]
            os.fsync(fd)
        except OSError as exc:
            raise AuditError(f"audit log {self.path}: cannot write it ({exc.strerror or exc})") from None
        finally:
            os.close(fd)
        return full

    # -- reading ----------------------------------------------------------------------------------
    def read(self) -> tuple[list[AuditEntry], list[AuditProblem]]:
        """All entries in file order, and the lines that are not entries. A missing file has none."""
        return read_entries(self.path)

    def entries(self) -> list[AuditEntry]:
        return self.read()[0]

    def last(self, action: str, leg: int, drive: str, outcomes: Iterable[str] = ("ok",)) -> AuditEntry | None:
        """The latest entry of `action` for `leg` on the drive with identity `drive` whose outcome
        is one of `outcomes`."""
        wanted = set(outcomes)
        for e in reversed(self.entries()):
            if e.action == action and e.leg == leg and e.drive == drive and e.outcome in wanted:
                return e
        return None


def read_entries(path: str | os.PathLike) -> tuple[list[AuditEntry], list[AuditProblem]]:
    """Parse an audit log file. Lines that are not entries come back as problems (line numbers
    from 1), never silently."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        return [], []
    except OSError as exc:
        raise AuditError(f"audit log {path}: cannot read it ({exc.strerror or exc})") from None
    entries: list[AuditEntry] = []
    problems: list[AuditProblem] = []
    for number, line in enumerate(raw.split(b"\n"), start=1):
        if not line.strip():
            continue
        try:
            entries.append(AuditEntry.from_json(json.loads(line.decode("utf-8"))))
        except (UnicodeDecodeError, ValueError) as exc:
            problems.append(AuditProblem(number, f"not an audit entry ({exc})"))
    return entries, problems


class AuditStopped(AuditError):
    """The audit sink stopped a run because `entry` (a push's "started" or "ok") could not be stored."""

    def __init__(self, entry: AuditEntry, message: str) -> None:
        super().__init__(message)
        self.entry = entry


class AuditSink:
    """The runner sink that writes the `AuditRecord` events of a procedure to `log`: the only
    writer of the audit log.

    Critical: the runner resumes the procedure only once the entry is on disk, so a push's
    "started" entry (its backup) is stored before anything is written to the drive, and if it
    cannot be stored the run stops there (AuditError: nothing was written). A final "ok" that
    cannot be stored stops the run too, saying the table is active. A refusal, cancellation or
    failure that cannot be stored does not hide the refusal itself: the problem is kept in
    `problems` for the front end to show, and the run goes on to report its outcome.
    """

    critical = True

    def __init__(self, log: AuditLog) -> None:
        self.log = log
        self.written: list[AuditEntry] = []
        self.problems: list[str] = []

    def handle(self, event: ev.Event) -> None:
        if not isinstance(event, AuditRecord):
            return
        entry = event.entry
        try:
            self.written.append(self.log.append(entry))
        except AuditError as exc:
            text = str(exc.args[0])
            if entry.outcome == AuditOutcome.STARTED:
                raise AuditStopped(entry, f"leg {entry.leg}: {text}; the {entry.action} was not started: nothing was "
                                   "written to the drive.") from None
            if entry.outcome == AuditOutcome.OK and entry.action != Action.VERIFY:
                raise AuditStopped(entry, f"leg {entry.leg}: the table was written and bank {entry.bank} is active, but "
                                   f"the audit log could not record it ({text}); its backup is in the 'started' entry "
                                   f"({entry.op_id}).") from None
            self.problems.append(text)

    def close(self, outcome: str) -> None:
        pass
