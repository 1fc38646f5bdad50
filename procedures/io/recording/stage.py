"""The stage of a leg's life a record belongs to (docs/session-schema.md, docs/catalog.md).

A calibration lab tells apart the state of the item (ISO/IEC 17025 7.8.4.1 d): *as found* (received,
before any adjustment), the *adjustment* (here a compensation table pushed or rolled back) and *as
left* (after the adjustment, verified). Drift, intervals and due dates come from as-found results
only; an as-left result says how well the adjustment worked, not how the leg aged.

A session's stage is derived from what the session recorded when it was created, never from a
front end's guess:

- the plan's kind "verification" (`station verify`, the UI's verification): ``as_left``;
- an import given its stage (`station import --stage`, plan "stage" "calibration" or
  "verification"): ``as_found`` or ``as_left``;
- an import of no stated stage (plan kind "import", rig "import") or a replay (rig "replay"):
  ``other`` (a replay re-runs a recording on replay devices, it measures no leg);
- a leg with a compensation table active at the start (`devices` `legN_compensation_table`
  enabled with points, or the older text `legN_compensation` "bank B active, N points from ..."):
  ``other``: the compensated leg was measured, which is neither its state as found nor a
  verification of an adjustment (`station sweep --yes` / the UI's question, station/services/jobs.py);
- otherwise ``as_found``: a calibration.

The session file keeps the stage as the root attribute `stage` (schema 1.2); `stage_of_session`
reads it, or derives it for an older file, which is how a catalog rebuilt from older files
classifies them. Audit entries: a push or rollback is ``adjustment``, a verification ``as_left``.
"""

from __future__ import annotations

import json
from typing import Any, Mapping, Protocol

from procedures.compensation.applied_table import TableState

AS_FOUND = "as_found"
ADJUSTMENT = "adjustment"
AS_LEFT = "as_left"
OTHER = "other"
STAGES = (AS_FOUND, ADJUSTMENT, AS_LEFT, OTHER)

LABELS = {AS_FOUND: "as found", ADJUSTMENT: "adjustment", AS_LEFT: "as left", OTHER: "other"}
"""How a stage is printed (history, legs, catalog status)."""

IMPORT_STAGES = {"calibration": AS_FOUND, "verification": AS_LEFT}
"""The stage of an import, by the plan "stage" `station import --stage` records."""

AUDIT_STAGES = {"push": ADJUSTMENT, "rollback": ADJUSTMENT, "verification": AS_LEFT}
"""The stage of a catalog record of an audit entry, by record kind."""


def active_tables(devices: Mapping[str, Any] | None) -> dict[int, str]:
    """leg -> what the session recorded of a compensation table active at its start, in words
    (TableState.text: "bank B active, N points from X mm every S mm"), for the legs with one.
    Reads the structure, the JSON `legN_compensation_table` (procedures/compensation/applied_table.py),
    and for files from before it the text `legN_compensation` the sweep records beside it."""
    structured: dict[int, TableState] = {}
    texts: dict[int, str] = {}
    for key, value in (devices or {}).items():
        if not (isinstance(key, str) and key.startswith("leg")):
            continue
        if key.endswith("_compensation_table") and key[3:-len("_compensation_table")].isdecimal():
            try:
                structured[int(key[3:-len("_compensation_table")])] = TableState.from_record(
                    json.loads(value) if isinstance(value, str) else dict(value))
            except (ValueError, TypeError, AttributeError):
                continue
        elif key.endswith("_compensation") and key[3:-len("_compensation")].isdecimal() and isinstance(value, str):
            texts[int(key[3:-len("_compensation")])] = value
    out = {leg: state.text for leg, state in structured.items() if state.active}
    # a leg with no readable structure (a file from before it): its text, when it names a table
    out.update({leg: text for leg, text in texts.items() if leg not in structured and " points from " in text})
    return dict(sorted(out.items()))


def session_stage(plan: Mapping[str, Any] | None, devices: Mapping[str, Any] | None, rig: str | None) -> str:
    """The stage of a session from its plan, devices and rig kind (module docstring)."""
    kind = (plan or {}).get("kind") if isinstance(plan, Mapping) else None
    if kind == "verification":
        return AS_LEFT
    stated = (plan or {}).get("stage") if isinstance(plan, Mapping) else None
    if kind == "import" and stated in IMPORT_STAGES:
        return IMPORT_STAGES[stated]
    if kind == "import" or rig in ("import", "replay"):
        return OTHER
    if active_tables(devices):
        return OTHER
    return AS_FOUND


class RecordedSession(Protocol):
    """What the stage is read from: procedures.io.recording.reader.Session (which imports this
    module, hence a protocol rather than that class)."""

    @property
    def attrs(self) -> Mapping[str, Any]: ...  # the root attributes
    @property
    def plan(self) -> Mapping[str, Any] | None: ...
    @property
    def devices(self) -> Mapping[str, Any] | None: ...


def stage_of_session(session: RecordedSession) -> str:
    """The stage of a read session: the recorded root attribute `stage` when it holds a known
    stage, else derived (files before schema 1.2)."""
    recorded = (session.attrs or {}).get("stage")
    if recorded in STAGES:
        return recorded
    return session_stage(session.plan, session.devices, (session.attrs or {}).get("rig"))
