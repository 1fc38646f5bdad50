"""Reading the audit log back: operations, filters, and which table each leg should hold.

An *operation* is what one push, rollback or verify did: a push or rollback writes a "started"
entry (with the backup) and then its final entry, linked by `op_id`; refusals logged by the
commands and verify entries are single entries. An operation with a "started" entry and no final
one was cut off (the process was killed, the power went): its outcome is `INTERRUPTED`, and the
log cannot tell whether the drive switched tables.

`leg_states` answers "which table is active on each leg, according to the log": the last
successful push or rollback, anything that makes it uncertain afterwards, and the last verify.
The drive itself is the authority (`station verify` reads its active table); the log says what
this station did to it.

Pure functions over procedures.compensation.audit; station/commands/audit.py presents them.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from datetime import date
from pathlib import Path
from typing import Any, Iterable

from procedures.compensation.audit import AuditEntry, AuditError, AuditProblem, read_entries
from procedures.vocabulary import InputError

INTERRUPTED = "INTERRUPTED"
"""Outcome of an operation with a "started" entry and no final entry."""

TABLE_ACTIONS = ("push", "rollback")


@dataclass(frozen=True)
class Operation:
    """One push / rollback / verify (or a refusal of one): its entries joined by `op_id`.

    `started` is the "started" entry (None for single-entry operations), `final` the entry with
    the outcome (None when interrupted). `index` orders operations as they began in the log.
    """

    key: str
    started: AuditEntry | None
    final: AuditEntry | None
    index: int

    @property
    def entry(self) -> AuditEntry:
        """The most telling entry: the final one, else the started one."""
        return self.final or self.started  # type: ignore[return-value]

    @property
    def interrupted(self) -> bool:
        return self.started is not None and self.final is None

    @property
    def outcome(self) -> str:
        return INTERRUPTED if self.interrupted else self.entry.outcome

    @property
    def action(self) -> str:
        return self.entry.action

    @property
    def leg(self) -> int:
        return self.entry.leg

    @property
    def time_utc(self) -> str:
        """When it began (the started entry's time, else the entry's)."""
        return (self.started or self.entry).time_utc

    @property
    def finished_utc(self) -> str:
        return self.final.time_utc if self.final is not None else ""

    @property
    def backup(self) -> dict[str, Any] | None:
        for e in (self.final, self.started):
            if e is not None and isinstance(e.backup, dict):
                return e.backup
        return None

    @property
    def changed_table(self) -> bool:
        """A push or rollback that ended with the new table active."""
        return self.action in TABLE_ACTIONS and self.outcome == "ok"

    def verify_verdict(self) -> str:
        """For a verify: "PASS" / "ABOVE" (residual RMS vs noise floor) when it was judged, else ""."""
        passed = self.entry.details.get("passed") if self.action == "verify" else None
        return "PASS" if passed is True else "ABOVE" if passed is False else ""

    def to_json(self, full: bool = False) -> dict[str, Any]:
        """The operation for `--json`: the joined fields; with `full`, also host, URL, source,
        backup summary, details and the ids of its entries. Non-finite numbers become null."""
        e = self.entry
        doc: dict[str, Any] = {
            "op_id": self.key, "time_utc": self.time_utc, "finished_utc": self.finished_utc or None,
            "operator": e.operator, "action": e.action, "leg": e.leg, "outcome": self.outcome,
            "interrupted": self.interrupted, "previous_bank": e.previous_bank, "bank": e.bank,
            "table_sha256": e.table_sha256 or None, "drive": e.drive or None, "message": e.message,
            "leg_serial": e.leg_serial, "station_id": e.station_id,
        }
        if self.action == "verify":
            doc["verdict"] = self.verify_verdict() or None
        if full:
            doc.update({
                "host": e.host or None, "drive_url": e.drive_url or None, "source": e.source,
                "backup": backup_summary(self.backup), "details": e.details,
                "entries": [{"id": x.id, "time_utc": x.time_utc, "outcome": x.outcome}
                            for x in (self.started, self.final) if x is not None],
            })
        return finite(doc)


def backup_summary(backup: dict[str, Any] | None) -> dict[str, Any] | None:
    """points, start_mm, spacing_mm, checksum, sha256 and bank of a backed-up table (not its entries)."""
    if not isinstance(backup, dict):
        return None
    fwd = backup.get("error_fwd_um")
    return finite({
        "bank": backup.get("bank"),
        "points": len(fwd) if isinstance(fwd, list) else None,
        "start_mm": backup.get("start_mm"),
        "spacing_mm": backup.get("spacing_mm"),
        "checksum": backup.get("checksum"),
        "sha256": backup.get("sha256"),
    })


def finite(value: Any) -> Any:
    """`value` with every NaN/inf float replaced by None (Python's json reads NaN tokens a
    hand-edited log may hold; strict JSON has none)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite(v) for v in value]
    return value


def join_operations(entries: Iterable[AuditEntry]) -> list[Operation]:
    """Entries joined into operations, in the order they began. Entries sharing an `op_id` form
    one operation ("started" + the final entry); entries without one stand alone."""
    slots: dict[str, list] = {}  # key -> [started, final, index]
    for i, e in enumerate(entries):
        key = e.op_id or e.id or f"line-entry-{i}"
        if not e.op_id and key in slots:  # two entries without op_id and the same id: keep both
            key = f"{key}#{i}"
        slot = slots.setdefault(key, [None, None, i])
        if e.outcome == "started" and slot[0] is None:
            slot[0] = e
        else:
            slot[1] = e  # the last final entry wins (one is written per operation)
    ops = [Operation(key, started, final, index) for key, (started, final, index) in slots.items()]
    return sorted(ops, key=lambda op: op.index)


@dataclass(frozen=True)
class AuditView:
    """What an audit log holds: its operations and the lines that are not entries."""

    path: Path
    operations: list[Operation]
    problems: list[AuditProblem]


def read_audit(path: str | os.PathLike) -> AuditView:
    """The operations of the audit log at `path`. AuditError (an InputError, naming the file and
    what to do) when it does not exist or cannot be read; bad lines come back as problems."""
    path = Path(path)
    if not path.exists():
        raise AuditError(f"audit log {path}: no such file; nothing was pushed, verified or rolled back with this "
                         "log yet, or it is elsewhere: name it with --audit FILE")
    entries, problems = read_entries(path)
    return AuditView(path, join_operations(entries), problems)


def parse_since(text: str) -> date:
    """A --since value, YYYY-MM-DD (UTC day). InputError otherwise."""
    try:
        return date.fromisoformat(text)
    except (TypeError, ValueError):
        raise InputError(f"--since {text}: not a date; give it as YYYY-MM-DD (a UTC day), e.g. --since 2025-03-01") from None


def select(ops: Iterable[Operation], *, leg: int | None = None, action: str | None = None,
           since: date | None = None, last: int | None = None) -> list[Operation]:
    """The operations of `leg`, of `action`, begun on or after the UTC day `since`; of those the
    `last` ones."""
    if last is not None and last < 1:
        raise InputError(f"--last {last}: give a number of operations, 1 or more")
    day = since.isoformat() if since is not None else ""
    out = [op for op in ops
           if (leg is None or op.leg == leg)
           and (action is None or op.action == action)
           and (not day or op.time_utc[:10] >= day)]
    return out[-last:] if last is not None else out


def find_operation(ops: Iterable[Operation], prefix: str) -> Operation:
    """The operation whose op_id starts with `prefix`. InputError when none or several do."""
    prefix = prefix.strip()
    if not prefix:
        raise InputError("--op: give an operation id (or its first characters), as listed by `station audit`")
    hits = [op for op in ops if op.key.startswith(prefix)]
    if not hits:
        raise InputError(f"--op {prefix}: no operation with that id in the audit log; `station audit` lists them")
    if len(hits) > 1:
        shown = ", ".join(op.key for op in hits[:5]) + (", ..." if len(hits) > 5 else "")
        raise InputError(f"--op {prefix}: {len(hits)} operations start with it ({shown}); give more characters")
    return hits[0]


@dataclass(frozen=True)
class LegState:
    """Which table leg `leg` should hold, according to the log.

    `table`: the last push or rollback that ended ok (None when there was none).
    `after`: the last push or rollback after it that was interrupted or failed, i.e. that may
    have left the drive otherwise (None when there is none).
    `verify`: the last verify of the leg after both of them (None when there is none).
    """

    leg: int
    table: Operation | None
    after: Operation | None
    verify: Operation | None

    @property
    def certain(self) -> bool:
        """False when an interrupted push/rollback leaves the log unable to say which table is active."""
        return not (self.after is not None and self.after.interrupted)

    @property
    def verify_matches(self) -> bool | None:
        """Whether the last verify found the table the log expects (None: no verify or no table)."""
        if self.verify is None or self.table is None or not self.certain or not self.verify.entry.table_sha256:
            return None
        return self.verify.entry.table_sha256 == self.table.entry.table_sha256

    def to_json(self) -> dict[str, Any]:
        def brief(op: Operation | None) -> dict[str, Any] | None:
            if op is None:
                return None
            e = op.entry
            return {"op_id": op.key, "action": op.action, "outcome": op.outcome, "time_utc": op.time_utc,
                    "table_sha256": e.table_sha256 or None, "bank": e.bank, "drive": e.drive or None,
                    **({"verdict": op.verify_verdict() or None} if op.action == "verify" else {})}

        return finite({"leg": self.leg, "certain": self.certain, "table": brief(self.table),
                       "after": brief(self.after), "verify": brief(self.verify),
                       "verify_matches": self.verify_matches})


def leg_states(ops: Iterable[Operation], legs: Iterable[int] | None = None) -> list[LegState]:
    """One LegState per leg that appears in `ops` (or per leg of `legs`, when given), by leg."""
    ops = list(ops)
    wanted = sorted(set(legs) if legs is not None else {op.leg for op in ops})
    states = []
    for leg in wanted:
        mine = [op for op in ops if op.leg == leg]
        table = next((op for op in reversed(mine) if op.changed_table), None)
        start = table.index if table is not None else -1
        after = next((op for op in reversed(mine) if op.index > start and op.action in TABLE_ACTIONS
                      and op.outcome in (INTERRUPTED, "failed")), None)
        since = max(start, after.index if after is not None else -1)
        verify = next((op for op in reversed(mine) if op.index > since and op.action == "verify"), None)
        states.append(LegState(leg, table, after, verify))
    return states
