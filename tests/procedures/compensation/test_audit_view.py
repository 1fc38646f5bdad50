"""Reading the audit log back (procedures.compensation.audit_view): entries joined into operations by op_id,
the interrupted case, filters, and which table each leg should hold according to the log."""

from __future__ import annotations

import json
import math
from datetime import date

import pytest

from procedures.compensation.audit import AuditEntry, AuditError, AuditLog
from procedures.compensation.audit_view import (
    INTERRUPTED,
    backup_summary,
    find_operation,
    join_operations,
    leg_states,
    parse_since,
    read_audit,
    select,
)
from procedures.vocabulary import InputError

DRIVE = "StationSim LegServo-402 s/n SIM-0001 fw 1.0.0"
OLD, NEW, NEWER = "a" * 64, "b" * 64, "c" * 64


def _backup(sha: str, bank: int, points: int = 3) -> dict:
    return {"bank": bank, "start_mm": -90.0, "spacing_mm": 90.0, "error_fwd_um": [0.1] * points,
            "error_rev_um": [-0.1] * points, "checksum": 4321, "sha256": sha}


def _push(log: AuditLog, op_id: str, leg: int, sha: str, prev_sha: str, bank: int, final: str | None = "ok",
          action: str = "push", time_utc: str = "") -> None:
    """The entries push_table writes: "started" with the backup, then the final one (unless None:
    the process died in between)."""
    base = dict(action=action, leg=leg, drive=DRIVE, drive_url="sim", table_sha256=sha, bank=bank,
                previous_bank=1 - bank, backup=_backup(prev_sha, 1 - bank), op_id=op_id,
                source={"path": "table.csv", "leg": leg})
    log.append(AuditEntry(outcome="started", message=f"{action} to bank {bank} started", time_utc=time_utc, **base))
    if final is not None:
        log.append(AuditEntry(outcome=final, message=f"{action} {final}", time_utc=time_utc, **base))


def _verify(log: AuditLog, leg: int, sha: str, passed: bool | None, outcome: str = "completed",
            time_utc: str = "") -> None:
    log.append(AuditEntry("verify", leg, outcome, f"verification {outcome}", DRIVE, "sim", table_sha256=sha, bank=1,
                          details={"passed": passed, "ratio": 0.9 if passed else 3.0}, time_utc=time_utc))


def test_started_and_final_entries_are_joined_into_one_operation(tmp_path):
    log = AuditLog(tmp_path / "audit.jsonl", operator="jdoe")
    _push(log, "op1", 1, NEW, OLD, 1)
    log.append(AuditEntry("push", 2, "refused", "bad table", operator="kim"))
    _verify(log, 1, NEW, True)
    ops = read_audit(log.path).operations
    assert [(op.action, op.leg, op.outcome) for op in ops] == [("push", 1, "ok"), ("push", 2, "refused"),
                                                               ("verify", 1, "completed")]
    push = ops[0]
    assert push.key == "op1" and push.started.outcome == "started" and push.final.outcome == "ok"
    assert push.time_utc == push.started.time_utc and push.finished_utc == push.final.time_utc
    assert push.entry.operator == "jdoe" and not push.interrupted and push.changed_table
    assert ops[1].started is None and ops[1].entry.operator == "kim" and not ops[1].interrupted
    assert ops[2].verify_verdict() == "PASS"
    full = push.to_json(full=True)
    assert full["backup"] == {"bank": 0, "points": 3, "start_mm": -90.0, "spacing_mm": 90.0, "checksum": 4321,
                              "sha256": OLD}
    assert [x["outcome"] for x in full["entries"]] == ["started", "ok"]


def test_a_started_entry_without_its_final_one_is_an_interrupted_operation(tmp_path):
    log = AuditLog(tmp_path / "audit.jsonl")
    _push(log, "op1", 1, NEW, OLD, 1)
    _push(log, "op2", 1, NEWER, NEW, 0, final=None)  # the station was killed while writing
    op = read_audit(log.path).operations[-1]
    assert op.interrupted and op.outcome == INTERRUPTED and op.final is None
    assert op.finished_utc == "" and op.entry.message == "push to bank 0 started"
    assert backup_summary(op.backup)["sha256"] == NEW, "the backup of the interrupted push is still shown"
    assert op.to_json()["interrupted"] is True and op.to_json()["outcome"] == INTERRUPTED
    assert not op.changed_table


def test_a_final_entry_whose_started_line_was_lost_still_shows(tmp_path):
    log = AuditLog(tmp_path / "audit.jsonl")
    _push(log, "op1", 3, NEW, OLD, 1)
    entries = log.entries()
    (op,) = join_operations(entries[1:])
    assert op.outcome == "ok" and not op.interrupted and op.started is None and op.backup["sha256"] == OLD


def test_filters_by_leg_action_day_and_count(tmp_path):
    log = AuditLog(tmp_path / "audit.jsonl")
    _push(log, "p1", 1, NEW, OLD, 1, time_utc="2025-03-01T08:00:00.000000Z")
    _verify(log, 1, NEW, True, time_utc="2025-03-01T09:00:00.000000Z")
    _push(log, "p2", 2, NEW, OLD, 1, time_utc="2025-03-02T08:00:00.000000Z")
    _push(log, "r1", 1, OLD, NEW, 0, action="rollback", time_utc="2025-03-03T23:59:59.999999Z")
    ops = read_audit(log.path).operations
    keys = lambda xs: [op.key for op in xs]  # noqa: E731
    assert keys(select(ops, leg=1)) == ["p1", ops[1].key, "r1"]
    assert keys(select(ops, action="rollback")) == ["r1"]
    assert keys(select(ops, action="verify", leg=2)) == []
    assert keys(select(ops, since=date(2025, 3, 2))) == ["p2", "r1"]
    assert keys(select(ops, since=date(2025, 3, 4))) == []
    assert keys(select(ops, last=2)) == ["p2", "r1"]
    assert keys(select(ops, leg=1, last=1)) == ["r1"], "--last counts after the other filters"
    with pytest.raises(InputError, match="--last 0"):
        select(ops, last=0)


def test_since_takes_a_day_and_names_the_format_otherwise():
    assert parse_since("2025-03-01") == date(2025, 3, 1)
    with pytest.raises(InputError, match="YYYY-MM-DD"):
        parse_since("yesterday")


def test_an_operation_is_found_by_the_first_characters_of_its_id(tmp_path):
    log = AuditLog(tmp_path / "audit.jsonl")
    _push(log, "abc123", 1, NEW, OLD, 1)
    _push(log, "abd456", 2, NEW, OLD, 1)
    ops = read_audit(log.path).operations
    assert find_operation(ops, "abc").key == "abc123"
    with pytest.raises(InputError, match="2 operations start with it"):
        find_operation(ops, "ab")
    with pytest.raises(InputError, match="no operation with that id"):
        find_operation(ops, "zz")


def test_the_table_per_leg_is_the_last_successful_push_or_rollback_and_the_verify_after_it(tmp_path):
    log = AuditLog(tmp_path / "audit.jsonl")
    _push(log, "p1", 1, NEW, OLD, 1)
    _verify(log, 1, NEW, False)                    # verified before the rollback: no longer relevant
    _push(log, "r1", 1, OLD, NEW, 0, action="rollback")
    _push(log, "p2", 1, NEWER, OLD, 1, final="refused")  # refused: nothing written, changes nothing
    _verify(log, 1, OLD, True)
    _push(log, "p3", 2, NEW, OLD, 1)
    _push(log, "p4", 2, NEWER, NEW, 0, final="failed")
    log.append(AuditEntry("push", 3, "refused", "bad table"))
    s1, s2, s3 = leg_states(read_audit(log.path).operations)
    assert (s1.leg, s1.table.key, s1.after, s1.certain) == (1, "r1", None, True)
    assert s1.table.entry.table_sha256 == OLD and s1.verify.verify_verdict() == "PASS" and s1.verify_matches is True
    assert (s2.table.key, s2.after.key, s2.after.outcome, s2.verify, s2.certain) == ("p3", "p4", "failed", None, True)
    assert (s3.table, s3.after, s3.verify, s3.verify_matches) == (None, None, None, None)
    doc = s1.to_json()
    assert doc["table"]["table_sha256"] == OLD and doc["verify"]["verdict"] == "PASS" and doc["verify_matches"] is True
    assert [s.leg for s in leg_states(read_audit(log.path).operations, legs=[2, 5])] == [2, 5]


def test_an_interrupted_push_makes_the_active_table_unknown_until_a_verify_reads_it(tmp_path):
    log = AuditLog(tmp_path / "audit.jsonl")
    _push(log, "p1", 1, NEW, OLD, 1)
    _verify(log, 1, NEW, True)
    _push(log, "p2", 1, NEWER, NEW, 0, final=None)
    (state,) = leg_states(read_audit(log.path).operations)
    assert state.table.key == "p1" and state.after.key == "p2" and not state.certain
    assert state.verify is None, "a verify from before the interrupted push says nothing about now"
    assert state.verify_matches is None
    _verify(log, 1, NEWER, True)
    (state,) = leg_states(read_audit(log.path).operations)
    assert state.verify.entry.table_sha256 == NEWER and not state.certain


def test_a_verify_that_found_another_table_does_not_match(tmp_path):
    log = AuditLog(tmp_path / "audit.jsonl")
    _push(log, "p1", 4, NEW, OLD, 1)
    _verify(log, 4, NEWER, True)  # someone changed the table at the drive panel
    (state,) = leg_states(read_audit(log.path).operations)
    assert state.verify_matches is False


def test_json_of_an_operation_is_strict_even_when_a_line_holds_nan(tmp_path):
    path = tmp_path / "audit.jsonl"
    AuditLog(path).append(AuditEntry("verify", 1, "completed", "ok", details={"ratio": 1.0}))
    with open(path, "a") as fh:  # Python's json reads NaN; a hand-edited or foreign line may hold it
        fh.write('{"action": "verify", "leg": 2, "outcome": "completed", "details": {"ratio": NaN, "x": [Infinity]}}\n')
    ops = read_audit(path).operations
    doc = ops[1].to_json(full=True)
    assert doc["details"] == {"ratio": None, "x": [None]}
    text = json.dumps([op.to_json(full=True) for op in ops], allow_nan=False)
    assert json.loads(text)[0]["details"]["ratio"] == 1.0
    assert not any(isinstance(v, float) and not math.isfinite(v) for v in doc["details"].values())


def test_bad_lines_are_problems_with_their_line_number(tmp_path):
    log = AuditLog(tmp_path / "audit.jsonl")
    _push(log, "p1", 1, NEW, OLD, 1)
    with open(log.path, "ab") as fh:
        fh.write(b'{"action": "push", "leg": 1, "outc')  # cut short by a crash
    _push(log, "p2", 1, NEWER, NEW, 0)
    view = read_audit(log.path)
    assert [p.line for p in view.problems] == [3]
    assert [op.key for op in view.operations] == ["p1", "p2"]


def test_a_missing_log_is_an_input_error_naming_the_file_and_what_to_do(tmp_path):
    with pytest.raises(AuditError) as info:
        read_audit(tmp_path / "nowhere.jsonl")
    assert isinstance(info.value, InputError)
    assert "nowhere.jsonl" in str(info.value) and "--audit FILE" in str(info.value)
