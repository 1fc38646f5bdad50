"""The shared vocabulary: one outcome type for how a sweep, a push or a verification ended, its values
the strings the session files and the audit log have always held."""

from __future__ import annotations

import json

from procedures.compensation.audit import FINAL_PUSH_OUTCOMES, Action, AuditEntry
from procedures.vocabulary import InputError, Outcome, PlanError, SchemaError


def test_the_outcomes_are_the_strings_in_the_files():
    assert {o.name: o.value for o in Outcome} == {
        "COMPLETED": "completed", "ABORTED": "aborted", "FAILED": "failed", "INCOMPLETE": "incomplete",
        "STARTED": "started", "OK": "ok", "REFUSED": "refused", "CANCELLED": "cancelled"}
    assert Outcome.written() == ("completed", "aborted", "failed")
    assert FINAL_PUSH_OUTCOMES == ("ok", "failed", "refused", "cancelled")
    assert [a.value for a in Action] == ["push", "rollback", "verify", "approve"]


def test_an_audit_line_of_an_older_station_reads_as_the_same_outcome():
    line = {"v": 1, "id": "a", "op_id": "b", "time_utc": "2026-01-01T00:00:00.000000Z", "operator": "ana",
            "host": "h", "action": "verify", "leg": 1, "drive": "d", "drive_url": "sim", "outcome": "completed",
            "message": "m"}
    entry = AuditEntry.from_json(json.loads(json.dumps(line)))
    # a verification's audit outcome is its sweep's outcome: one type, no conversion between two
    assert entry.outcome == Outcome.COMPLETED and Outcome(entry.outcome) is Outcome.COMPLETED
    assert entry.action == Action.VERIFY
    assert json.loads(json.dumps({"outcome": Outcome.FAILED})) == {"outcome": "failed"}


def test_the_input_errors_are_value_errors_with_their_message():
    for kind in (InputError, SchemaError, PlanError):
        err = kind("plan.json: targets_mm[2] = 95 mm is outside the soft limits -90..90 mm; fix the plan")
        assert isinstance(err, ValueError) and isinstance(err, InputError)
        assert str(err).startswith("plan.json: targets_mm[2]")
