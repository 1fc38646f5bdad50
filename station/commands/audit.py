"""`station audit`: show the audit log, one line per push / verify / rollback, and which table
each leg should hold. The reading, joining and per-leg summary are station.services.audit_query;
this module only fills the query and prints the answer."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import json
import sys

from station.services.audit_query import ACTION_NAMES
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
    p.add_argument("--action", choices=list(ACTION_NAMES), help="only this action")
    p.add_argument("--since", type=V.DATE.argtype(), metavar="YYYY-MM-DD", help="only operations begun on or after this day (UTC)")
    p.add_argument("--last", type=V.COUNT.argtype(), metavar="N", help="only the last N operations (after the other filters)")
    p.add_argument("--op", type=V.OP_ID.argtype(), metavar="OP_ID", help="show one operation in full (its id or first characters, column 'op')")
    p.add_argument("--json", action="store_true", help="print strict JSON instead of text")


def run(args) -> int:
    from station.services.audit_query import AuditQuery, format_leg_state, format_operation, format_table, query_audit

    a = query_audit(AuditQuery(audit=args.audit, config=args.config, leg=args.leg, action=args.action,
                               since=args.since, last=args.last, op=args.op))
    _warn_problems(a)
    if args.json:
        print(json.dumps(a.to_json(), indent=2, allow_nan=False))
        return 0
    if a.operation is not None:
        print("\n".join(format_operation(a.operation)))
        return 0
    print(f"audit log {a.path}: {a.total} operation{'s' if a.total != 1 else ''}"
          + (f", {len(a.operations)} shown" if len(a.operations) != a.total else ""))
    if a.operations:
        print("\n".join(format_table(a.operations)))
    else:
        print("no operation matches" if a.total else "no entries")
    if a.legs:
        print()
        print("table per leg, according to this log (the drive is the authority: `station verify` reads it):")
        for s in a.legs:
            print(f"  {format_leg_state(s)}")
    return 0


def _warn_problems(a) -> None:
    for line, reason in a.problems[:MAX_PROBLEMS_SHOWN]:
        print(f"warning: {a.path}, line {line}: {reason} (skipped; left as is: the log is append-only)",
              file=sys.stderr)
    more = len(a.problems) - MAX_PROBLEMS_SHOWN
    if more > 0:
        print(f"warning: {a.path}: {more} more lines are not audit entries", file=sys.stderr)
