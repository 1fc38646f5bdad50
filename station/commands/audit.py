"""`station audit`: show the audit log, one line per push / verify / rollback, and which table
each leg should hold. The joining and the per-leg summary are procedures.compensation.audit_view; this
module only presents them."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import json
import sys
from typing import Any

from procedures.compensation.audit import ACTIONS
from procedures.vocabulary import InputError
from procedures.compensation.audit_view import (
    INTERRUPTED,
    AuditView,
    LegState,
    Operation,
    backup_summary,
    find_operation,
    leg_states,
    parse_since,
    read_audit,
    select,
)
from station.services.config import AUDIT_NAME

NAME = "audit"
HELP = "show the audit log: every push, verify and rollback, and which table each leg should hold"
DESCRIPTION = (
    "List the operations in the audit log (a push's or rollback's 'started' entry joined with its final "
    "entry; one whose final entry is missing, e.g. a killed push, shows as INTERRUPTED), filtered by leg, "
    "action, day or count, then the table each leg should hold according to the log and its last verify. "
    "--op shows one operation in full, with the backup it recorded. Reads only. See docs/compensation.md."
)

MAX_PROBLEMS_SHOWN = 10


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--audit", type=V.AUDIT_TO_READ.argtype(), metavar="FILE", help=f"audit log (default <recordings_dir>/{AUDIT_NAME}, i.e. runs/{AUDIT_NAME})")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML whose recordings_dir holds the audit log")
    p.add_argument("--leg", type=V.LEG.argtype(), metavar="N", help="only this leg")
    p.add_argument("--action", choices=[str(a.value) for a in ACTIONS], help="only this action")
    p.add_argument("--since", type=V.DATE.argtype(), metavar="YYYY-MM-DD", help="only operations begun on or after this day (UTC)")
    p.add_argument("--last", type=V.COUNT.argtype(), metavar="N", help="only the last N operations (after the other filters)")
    p.add_argument("--op", type=V.OP_ID.argtype(), metavar="OP_ID", help="show one operation in full (its id or first characters, column 'op')")
    p.add_argument("--json", action="store_true", help="print strict JSON instead of text")


def run(args) -> int:
    from station.commands._table_cli import audit_log
    from station.services.config import LEG_COUNT, load_config

    cfg = load_config(args.config)
    path = audit_log(args, cfg).path
    if args.leg is not None:
        if not 1 <= args.leg <= LEG_COUNT:
            raise InputError(f"--leg {args.leg}: leg numbers run from 1 to {LEG_COUNT}")
    since = parse_since(args.since) if args.since else None
    view = read_audit(path)
    _warn_problems(view)
    if args.op:
        op = find_operation(view.operations, args.op)
        if args.json:
            _print_json({"audit_log": str(view.path), "problems": _problems(view), "operation": op.to_json(full=True)})
        else:
            print("\n".join(format_operation(op)))
        return 0
    ops = select(view.operations, leg=args.leg, action=args.action, since=since, last=args.last)
    states = leg_states(view.operations, legs=[args.leg] if args.leg is not None else None)
    if args.json:
        _print_json({"audit_log": str(view.path), "problems": _problems(view),
                     "operations": [op.to_json() for op in ops], "legs": [s.to_json() for s in states]})
        return 0
    total = len(view.operations)
    print(f"audit log {view.path}: {total} operation{'s' if total != 1 else ''}"
          + (f", {len(ops)} shown" if len(ops) != total else ""))
    if ops:
        print("\n".join(format_table(ops)))
    else:
        print("no operation matches" if total else "no entries")
    if states:
        print()
        print("table per leg, according to this log (the drive is the authority: `station verify` reads it):")
        for s in states:
            print(f"  {format_leg_state(s)}")
    return 0


# -- presentation ---------------------------------------------------------------------------------

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


def _problems(view: AuditView) -> list[dict[str, Any]]:
    return [{"line": p.line, "reason": p.reason} for p in view.problems]


def _warn_problems(view: AuditView) -> None:
    for p in view.problems[:MAX_PROBLEMS_SHOWN]:
        print(f"warning: {view.path}, line {p.line}: {p.reason} (skipped; left as is: the log is append-only)",
              file=sys.stderr)
    more = len(view.problems) - MAX_PROBLEMS_SHOWN
    if more > 0:
        print(f"warning: {view.path}: {more} more lines are not audit entries", file=sys.stderr)


def _print_json(doc: dict[str, Any]) -> None:
    print(json.dumps(doc, indent=2, allow_nan=False))
