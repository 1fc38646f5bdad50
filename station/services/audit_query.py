"""The audit log read for a front end (issue 32 part 1: front ends reach procedures only through
services): `station audit` fills an `AuditQuery`; `query_audit` finds the log, checks the
filters, joins the entries into operations and says which table each leg should hold
(procedures.compensation.audit_view); the `format_*` functions are its text, one line per
operation, per leg, or one operation in full."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from procedures.compensation.audit import ACTIONS
from procedures.compensation.audit_view import INTERRUPTED, LegState, Operation, backup_summary
from procedures.vocabulary import InputError

if TYPE_CHECKING:
    from station.services.config import StationConfig

ACTION_NAMES: tuple[str, ...] = tuple(str(a.value) for a in ACTIONS)
"""The actions an audit entry names (push, verify, rollback, ...): what a query may filter by."""


@dataclass
class AuditQuery:
    """What to show of the audit log `audit` (None: <recordings_dir>/audit.jsonl of the station
    config `config`). Filters: `leg`, `action` (one of ACTION_NAMES), `since` (YYYY-MM-DD, UTC),
    `last` (the last N after the other filters); `op`: one operation (its id or first characters)."""

    audit: str | None = None
    config: Path | None = None
    leg: int | None = None
    action: str | None = None
    since: str | None = None
    last: int | None = None
    op: str | None = None


@dataclass
class AuditAnswer:
    """What `query_audit` found. `problems`: (line, reason) of the lines that are not audit
    entries (skipped); `operation`: the one asked for with `op`; else `operations` (filtered),
    `total` (all in the log) and `legs` (the table each leg should hold)."""

    path: Path
    problems: list[tuple[int, str]]
    total: int
    operation: Operation | None = None
    operations: list[Operation] = field(default_factory=list)
    legs: list[LegState] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        doc: dict[str, Any] = {"audit_log": str(self.path),
                               "problems": [{"line": line, "reason": reason} for line, reason in self.problems]}
        if self.operation is not None:
            doc["operation"] = self.operation.to_json(full=True)
        else:
            doc["operations"] = [op.to_json() for op in self.operations]
            doc["legs"] = [s.to_json() for s in self.legs]
        return doc


def query_audit(query: AuditQuery, cfg: StationConfig | None = None) -> AuditAnswer:
    """Read the station's audit log and answer `query`; InputError for a leg outside the
    station's, a bad day or an operation id that names none or several."""
    from procedures.compensation.audit_view import find_operation, leg_states, parse_since, read_audit
    from station.services.config import LEG_COUNT
    from station.services.session_identity import station_audit_log
    from station.services.job import config_or_load

    q = query
    cfg = config_or_load(cfg, q.config)
    path = station_audit_log(cfg, q.audit).path
    if q.leg is not None and not 1 <= q.leg <= LEG_COUNT:
        raise InputError(f"--leg {q.leg}: leg numbers run from 1 to {LEG_COUNT}")
    since = parse_since(q.since) if q.since else None
    view = read_audit(path)
    answer = AuditAnswer(Path(view.path), [(p.line, p.reason) for p in view.problems], len(view.operations))
    if q.op:
        answer.operation = find_operation(view.operations, q.op)
        return answer
    from procedures.compensation.audit_view import select

    answer.operations = select(view.operations, leg=q.leg, action=q.action, since=since, last=q.last)
    answer.legs = leg_states(view.operations, legs=[q.leg] if q.leg is not None else None)
    return answer


# -- the text of an operation ----------------------------------------------------------------------

def _when(time_utc: str) -> str:
    """'2025-03-04 10:12:01' from '2025-03-04T10:12:01.123456Z' ('?' when missing)."""
    return time_utc[:19].replace("T", " ") if time_utc else "?"


def _sha(sha: str | None) -> str:
    return sha[:12] if sha else "-"


def _banks(op: Operation) -> str:
    e = op.entry
    if e.bank is None:
        return "-"
    return f"{e.previous_bank}->{e.bank}" if e.previous_bank is not None else str(e.bank)


def outcome_text(op: Operation) -> str:
    if op.outcome == INTERRUPTED:
        return "INTERRUPTED (no final entry)"
    verdict = op.verify_verdict()
    return f"{op.outcome} {verdict}" if verdict else op.outcome


COLUMNS = ("op", "time (UTC)", "operator", "action", "leg", "outcome", "bank", "table sha256", "drive", "message")


def format_table(ops: list[Operation]) -> list[str]:
    """A header and one line per operation; columns padded to their widest cell, message last."""
    rows = [[op.key[:8], _when(op.time_utc), op.entry.operator or "-", op.action, str(op.leg), outcome_text(op),
             _banks(op), _sha(op.entry.table_sha256), op.entry.drive or "-", op.entry.message] for op in ops]
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(COLUMNS[:-1])]

    def line(cells) -> str:
        padded = [c.rjust(w) if h == "leg" else c.ljust(w) for c, w, h in zip(cells, widths, COLUMNS)]
        return "  ".join(padded + [cells[-1]]).rstrip()

    return [line(COLUMNS)] + [line(r) for r in rows]


def format_leg_state(s: LegState) -> str:
    text = f"leg {s.leg}: "
    if s.after is not None and s.after.interrupted:
        a, backup = s.after.entry, backup_summary(s.after.backup) or {}
        text += (f"UNKNOWN: {a.action} {_when(s.after.time_utc)} (op {s.after.key[:8]}) was INTERRUPTED (no final "
                 f"entry): bank {a.bank} ({_sha(a.table_sha256)}, the new table) or bank {a.previous_bank} "
                 f"({_sha(backup.get('sha256'))}, the backup) is active; read the drive")
    elif s.table is None:
        text += "no successful push or rollback in this log"
    else:
        t = s.table.entry
        text += (f"{_sha(t.table_sha256)} in bank {t.bank}, {s.table.action} ok {_when(s.table.time_utc)} "
                 f"(op {s.table.key[:8]})")
        if s.after is not None:
            text += f"; then {s.after.action} {_when(s.after.time_utc)} failed: {s.after.entry.message}"
    if s.verify is None:
        return text + ("; not verified since" if s.table is not None or s.after is not None else "")
    v = s.verify
    text += f"; verify {_when(v.time_utc)}: {outcome_text(v)}"
    if s.verify_matches is False:
        text += f", but it found {_sha(v.entry.table_sha256)} active: changed outside this log"
    elif s.after is not None and s.after.interrupted and v.entry.table_sha256:
        a = s.after.entry
        which = ("the new table" if v.entry.table_sha256 == a.table_sha256
                 else "the backup" if v.entry.table_sha256 == (backup_summary(s.after.backup) or {}).get("sha256")
                 else "neither")
        text += f", found {_sha(v.entry.table_sha256)} active ({which})"
    return text


def format_operation(op: Operation) -> list[str]:
    """One operation in full: every field, the backup table's summary and the details."""
    e = op.entry
    lines = [f"operation {op.key}: {op.action}, leg {op.leg}", f"  outcome        {outcome_text(op)}"]
    if op.started is not None:
        lines.append(f"  started        {op.started.time_utc} (entry {op.started.id})")
    if op.final is not None:
        lines.append(f"  {'finished' if op.started is not None else 'time':<15}{op.final.time_utc} (entry {op.final.id})")
    lines += [
        f"  operator       {e.operator or '-'}" + (f" on {e.host}" if e.host else ""),
        f"  drive          {e.drive or '- (not contacted)'}" + (f"  via {e.drive_url}" if e.drive_url else ""),
        f"  bank           {_banks(op).replace('->', ' -> ')}",
        f"  table sha256   {e.table_sha256 or '-'}",
    ]
    if isinstance(e.source, dict):
        lines.append("  source         " + ", ".join(f"{k} {v}" for k, v in e.source.items()))
    lines.append(f"  message        {e.message}")
    backup = backup_summary(op.backup)
    if backup is not None:
        lines.append("  backup         the table active before (entries in full in the log):")
        for key in ("bank", "points", "start_mm", "spacing_mm", "checksum", "sha256"):
            lines.append(f"    {key:<13}{_value(backup.get(key))}")
    if e.details:
        lines.append("  details")
        lines += [f"    {k:<28} {_value(v)}" for k, v in _flatten(e.details)]
    if op.interrupted:
        lines.append(f"  note: the process stopped after recording the backup: either bank {e.bank} (the new table) "
                     f"or bank {e.previous_bank} (the backup) is active; read the drive (`station verify`, "
                     "or `g` on the TUI's Compensation screen)")
    return lines


def _flatten(d: dict[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    for k, v in d.items():
        if isinstance(v, dict) and v:
            out += _flatten(v, f"{prefix}{k}.")
        else:
            out.append((f"{prefix}{k}", v))
    return out


def _value(v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, list):
        return f"[{len(v)} values]" if len(v) > 6 else json.dumps(v)
    return str(v)
