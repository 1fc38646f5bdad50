"""`station audit` through station.cli.main, on an audit log written by real `station push`,
`rollback` and `verify` runs on the simulated drive (and one push interrupted mid-write): one line
per operation, the interrupted case, filters, --op, strict --json, bad lines, a missing log."""

from __future__ import annotations

import json
import logging
import shutil
from datetime import date, timedelta
from pathlib import Path

import pytest

from drivers.modbus.client import ModbusServoAxis
from procedures.compensation.audit import read_entries
from procedures.compensation.push import quantize, table_sha256
from procedures.compensation.table import CompTable, LegTable, table_csv_text
from station.cli import main

AUDIT = Path("runs/audit.jsonl")


def _leg_table(leg: int, slope_um_per_mm: float) -> LegTable:
    x = [-90.0 + 6.0 * i for i in range(31)]
    return LegTable(leg, -90.0, 6.0, tuple(slope_um_per_mm * v for v in x), tuple(slope_um_per_mm * v + 0.5 for v in x))


def _sha(leg: int, slope: float) -> str:
    return table_sha256(quantize(_leg_table(leg, slope).to_bank()))


def station(capsys, *argv: str) -> tuple[int, str, str]:
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture(scope="module")
def history(tmp_path_factory) -> Path:
    """An audit log made by the real commands on the simulated drive:
    leg 1: push A, push B, rollback (A again), verify; leg 2: push A, then a push of B that dies
    mid-write (Ctrl-C while the table goes to the drive: "started" and no final entry);
    leg 3: a push refused (no such CSV)."""
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    root = tmp_path_factory.mktemp("audit-history")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(root)
        for name, slope in (("a.csv", 0.01), ("b.csv", 0.02)):
            Path(name).write_text(table_csv_text(CompTable({leg: _leg_table(leg, slope) for leg in (1, 2)})))
        for argv in (["push", "a.csv", "--leg", "1"], ["push", "b.csv", "--leg", "1"], ["rollback", "--leg", "1"],
                     ["push", "a.csv", "--leg", "2"]):
            assert main(argv + ["--sim", "--yes"]) == 0, argv
        assert main(["verify", "--leg", "1", "--sim", "--cycles", "2", "--noise-seed", "4", "--out", "v.h5"]) in (0, 1)

        def killed(self, bank, table):
            raise KeyboardInterrupt  # the operator's Ctrl-C, or a kill, while the table is being written

        mp.setattr(ModbusServoAxis, "write_table", killed)
        assert main(["push", "b.csv", "--leg", "2", "--sim", "--yes"]) == 130
        mp.undo()
        mp.chdir(root)
        assert main(["push", "missing.csv", "--leg", "3", "--sim", "--yes"]) == 2
    return root / AUDIT


@pytest.fixture
def log(history, tmp_path, monkeypatch) -> Path:
    """A copy of the history's audit log at runs/audit.jsonl in a fresh working directory."""
    monkeypatch.chdir(tmp_path)
    AUDIT.parent.mkdir()
    shutil.copy(history, AUDIT)
    return AUDIT


def _rows(out: str) -> list[str]:
    """The operation lines of the text output (between the header and the blank line)."""
    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("op "))
    end = lines.index("", start)
    return lines[start + 1:end]


def _summary(out: str) -> dict[int, str]:
    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("table per leg"))
    return {int(line.split()[1].rstrip(":")): line.strip() for line in lines[start + 1:] if line.strip()}


def test_one_line_per_operation_joining_started_and_final_entries(capsys, log):
    entries, problems = read_entries(log)
    assert problems == []
    rc, out, err = station(capsys, "audit")
    assert rc == 0 and err == ""
    assert out.splitlines()[0] == f"audit log {log}: 7 operations"
    header = out.splitlines()[1].split()
    assert header[:4] == ["op", "time", "(UTC)", "operator"] and header[-2:] == ["drive", "message"]
    rows = _rows(out)
    assert len(rows) == 7 and len(entries) == 11, "4 started+final pairs joined; the interrupted push, verify and refusal alone"
    push_a1, push_b1, rollback1, push_a2, verify1, killed2, refused3 = rows
    a1, b1, a2, b2 = _sha(1, 0.01), _sha(1, 0.02), _sha(2, 0.01), _sha(2, 0.02)
    assert push_a1.split()[4:10] == ["push", "1", "ok", "0->1", a1[:12], "StationSim"]
    assert push_b1.split()[4:9] == ["push", "1", "ok", "1->0", b1[:12]]
    assert rollback1.split()[4:9] == ["rollback", "1", "ok", "0->1", a1[:12]]
    assert "rollback ok: bank 1 active on leg 1" in rollback1
    assert "s/n SIM-0001 fw 1.0.0" in push_a1 and "s/n SIM-0002 fw 1.0.0" in push_a2
    (verify_entry,) = [e for e in entries if e.action == "verify"]
    verdict = "PASS" if verify_entry.details["passed"] else "ABOVE"
    assert verify1.split()[4:9] == ["verify", "1", "completed", verdict, "1"]
    assert a1[:12] in verify1 and verify_entry.message in verify1
    assert killed2.split()[4:11] == ["push", "2", "INTERRUPTED", "(no", "final", "entry)", "1->0"]
    assert b2[:12] in killed2 and "push to bank 0 started; backup of bank 1 recorded" in killed2
    assert refused3.split()[4:10] == ["push", "3", "refused", "-", "-", "-"] and "missing.csv" in refused3
    ops = {e.op_id for e in entries if e.op_id}
    assert {row.split()[0] for row in rows[:4] + [killed2]} == {op[:8] for op in ops}
    assert all(row.split()[1].startswith(entries[0].time_utc[:4]) for row in rows)


def test_the_table_per_leg_summary(capsys, log):
    rc, out, err = station(capsys, "audit")
    summary = _summary(out)
    assert sorted(summary) == [1, 2, 3]
    a1, a2, b2 = _sha(1, 0.01), _sha(2, 0.01), _sha(2, 0.02)
    assert summary[1].startswith(f"leg 1: {a1[:12]} in bank 1, rollback ok ")
    assert "; verify " in summary[1] and ": completed " in summary[1] and "changed outside" not in summary[1]
    assert summary[2].startswith("leg 2: UNKNOWN: push ") and "INTERRUPTED (no final entry)" in summary[2]
    assert f"bank 0 ({b2[:12]}, the new table) or bank 1 ({a2[:12]}, the backup) is active" in summary[2]
    assert summary[3] == "leg 3: no successful push or rollback in this log"


def test_op_shows_one_operation_in_full_with_its_backup(capsys, log):
    entries, _ = read_entries(log)
    killed = [e for e in entries if e.leg == 2 and e.outcome == "started"][-1]
    rc, out, err = station(capsys, "audit", "--op", killed.op_id[:6])
    assert rc == 0, err
    lines = out.splitlines()
    assert lines[0] == f"operation {killed.op_id}: push, leg 2"
    assert "  outcome        INTERRUPTED (no final entry)" in lines and "finished" not in out
    assert f"  table sha256   {_sha(2, 0.02)}" in lines and "  bank           1 -> 0" in lines
    assert "source         leg 2, path b.csv, sha256 " in out
    backup = {line.split()[0]: line.split()[1] for line in lines[lines.index(
        "  backup         the table active before (entries in full in the log):") + 1:][:6]}
    assert backup == {"bank": "1", "points": "31", "start_mm": "-90", "spacing_mm": "6",
                      "checksum": str(killed.backup["checksum"]), "sha256": _sha(2, 0.01)}
    assert "note: the process stopped after recording the backup" in out


def test_op_of_a_verify_shows_its_details(capsys, log):
    entries, _ = read_entries(log)
    (v,) = [e for e in entries if e.action == "verify"]
    rc, out, err = station(capsys, "audit", "--op", v.id)
    assert rc == 0, err
    assert f"    {'session':<28} v.h5" in out
    assert f"    {'after.rms_um':<28} {v.details['after']['rms_um']:.6g}" in out
    assert f"    {'passed':<28} {v.details['passed']}" in out


@pytest.mark.parametrize("argv, want", [
    (["--leg", "1"], [("push", "1"), ("push", "1"), ("rollback", "1"), ("verify", "1")]),
    (["--action", "rollback"], [("rollback", "1")]),
    (["--action", "push", "--leg", "2"], [("push", "2"), ("push", "2")]),
    (["--last", "2"], [("push", "2"), ("push", "3")]),
    (["--leg", "1", "--last", "1"], [("verify", "1")]),
    (["--since", "DAY OF THE FIRST ENTRY"], None),  # all of them
])
def test_filters(capsys, log, argv, want):
    first_day = read_entries(log)[0][0].time_utc[:10]
    argv = [first_day if a == "DAY OF THE FIRST ENTRY" else a for a in argv]
    rc, out, err = station(capsys, "audit", *argv)
    assert rc == 0, err
    got = [tuple(row.split()[4:6]) for row in _rows(out)]
    if want is None:
        assert len(got) == 7 and out.splitlines()[0].endswith(": 7 operations")
    else:
        assert got == want and out.splitlines()[0].endswith(f": 7 operations, {len(want)} shown")
    if "--leg" in argv:
        assert list(_summary(out)) == [int(argv[argv.index("--leg") + 1])]


def test_since_a_later_day_shows_none(capsys, log):
    last_day = date.fromisoformat(read_entries(log)[0][-1].time_utc[:10])
    tomorrow = (last_day + timedelta(days=1)).isoformat()
    rc, out, err = station(capsys, "audit", "--since", tomorrow)
    assert rc == 0 and "no operation matches" in out
    assert "leg 2: UNKNOWN" in out, "the summary stands on the whole log, not on the filtered lines"


@pytest.mark.parametrize("argv, words", [
    (["--since", "last week"], "argument --since: 'last week' is not a date; give it as YYYY-MM-DD"),
    (["--last", "0"], "argument --last: '0' is outside 1 .. 1000000; give a count as a whole number"),
    (["--leg", "9"], "argument --leg: '9' is outside 1 .. 6; give a leg number"),
    (["--op", "zzzz"], "--op zzzz: no operation with that id in the audit log"),
])
def test_bad_arguments_are_one_line(capsys, log, argv, words):
    rc, out, err = station(capsys, "audit", *argv)
    assert rc == 2 and out == ""
    assert err.startswith(f"station audit: error: {words}") and err.count("\n") == 1


def _strict(text: str):
    def no_constant(name):
        raise AssertionError(f"not strict JSON: {name}")

    return json.loads(text, parse_constant=no_constant)


def test_json_is_strict_and_holds_the_joined_operations_and_the_legs(capsys, log):
    with open(log, "a") as fh:  # a foreign line with NaN, which Python's json would otherwise pass through
        fh.write('{"action": "verify", "leg": 4, "outcome": "completed", "op_id": "f00d", "details": {"ratio": NaN}}\n')
    rc, out, err = station(capsys, "audit", "--json")
    assert rc == 0 and err == ""
    doc = _strict(out)
    assert doc["audit_log"] == str(log) and doc["problems"] == []
    ops = doc["operations"]
    assert [(o["action"], o["leg"], o["outcome"]) for o in ops] == [
        ("push", 1, "ok"), ("push", 1, "ok"), ("rollback", 1, "ok"), ("push", 2, "ok"), ("verify", 1, "completed"),
        ("push", 2, "INTERRUPTED"), ("push", 3, "refused"), ("verify", 4, "completed")]
    assert ops[5]["interrupted"] is True and ops[5]["finished_utc"] is None and ops[0]["interrupted"] is False
    assert ops[0]["table_sha256"] == _sha(1, 0.01) and (ops[0]["previous_bank"], ops[0]["bank"]) == (0, 1)
    legs = {s["leg"]: s for s in doc["legs"]}
    assert legs[1]["table"]["action"] == "rollback" and legs[1]["verify_matches"] is True
    assert legs[2]["certain"] is False and legs[2]["after"]["outcome"] == "INTERRUPTED"
    assert legs[3]["table"] is None
    rc, out, err = station(capsys, "audit", "--json", "--op", "f00d")
    assert rc == 0 and _strict(out)["operation"]["details"] == {"ratio": None}


def test_json_of_one_operation_has_the_backup_summary(capsys, log):
    entries, _ = read_entries(log)
    push = next(e for e in entries if e.action == "push" and e.outcome == "ok" and e.leg == 1)
    rc, out, err = station(capsys, "audit", "--op", push.op_id, "--json")
    op = _strict(out)["operation"]
    assert op["backup"] == {"bank": 0, "points": 0, "start_mm": push.backup["start_mm"],
                            "spacing_mm": push.backup["spacing_mm"], "checksum": push.backup["checksum"],
                            "sha256": push.backup["sha256"]}
    assert [x["outcome"] for x in op["entries"]] == ["started", "ok"] and op["source"]["path"] == "a.csv"


def test_lines_that_are_not_json_are_warned_about_with_their_line_number(capsys, log):
    n = len(log.read_text().splitlines())
    with open(log, "ab") as fh:
        fh.write(b'{"action": "push", "leg": 2, "outc')  # a crash in the middle of a write
    rc, out, err = station(capsys, "audit")
    assert rc == 0 and "Traceback" not in err
    assert err.startswith(f"warning: {log}, line {n + 1}: not an audit entry (") and err.count("\n") == 1
    assert len(_rows(out)) == 7, "the entries around it are still shown"
    rc, out, err = station(capsys, "audit", "--json")
    assert _strict(out)["problems"][0]["line"] == n + 1 and f"line {n + 1}" in err


def test_a_missing_log_is_one_line_naming_it_and_what_to_do(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, out, err = station(capsys, "audit")
    assert rc == 2 and out == ""
    assert err == ("station audit: error: audit log runs/audit.jsonl: no such file; nothing was pushed, verified or "
                   "rolled back with this log yet, or it is elsewhere: name it with --audit FILE\n")
    rc, out, err = station(capsys, "audit", "--audit", "elsewhere/log.jsonl")
    assert rc == 2 and "audit log elsewhere/log.jsonl: no such file" in err and err.count("\n") == 1


def test_audit_and_config_choose_the_file(capsys, log, tmp_path):
    shutil.copy(log, tmp_path / "copy.jsonl")
    rc, out, err = station(capsys, "audit", "--audit", str(tmp_path / "copy.jsonl"), "--last", "1")
    assert rc == 0 and out.startswith(f"audit log {tmp_path / 'copy.jsonl'}: 7 operations, 1 shown")
    (tmp_path / "lab").mkdir()
    shutil.copy(log, tmp_path / "lab" / "audit.jsonl")
    (tmp_path / "station.toml").write_text('[station]\nrecordings_dir = "lab"\n')
    rc, out, err = station(capsys, "audit", "--config", "station.toml", "--action", "rollback")
    assert rc == 0 and out.startswith("audit log lab/audit.jsonl: 7 operations, 1 shown")


def test_the_summary_says_what_a_later_failure_or_a_verify_found(capsys, tmp_path, monkeypatch):
    from procedures.compensation.audit import AuditEntry, AuditLog

    monkeypatch.chdir(tmp_path)
    log = AuditLog(AUDIT, operator="jdoe")
    old, new, newer = "a" * 64, "b" * 64, "c" * 64

    def push(op_id: str, leg: int, sha: str, prev: str, bank: int, final: str | None, message: str = "") -> None:
        base = dict(action="push", leg=leg, drive="D", table_sha256=sha, bank=bank, previous_bank=1 - bank, op_id=op_id,
                    backup={"bank": 1 - bank, "error_fwd_um": [], "error_rev_um": [], "sha256": prev})
        log.append(AuditEntry(outcome="started", message="started", **base))
        if final:
            log.append(AuditEntry(outcome=final, message=message or final, **base))

    push("p1", 1, new, old, 1, "ok")
    push("p2", 1, newer, new, 0, "failed", "leg 1: push failed while writing bank 0: timeout. The previous table is still active")
    push("p3", 2, new, old, 1, "ok")
    log.append(AuditEntry("verify", 2, "completed", "v", "D", table_sha256=newer, bank=1, details={"passed": True}))
    push("p4", 3, new, old, 1, "ok")
    push("p5", 3, newer, new, 0, None)
    log.append(AuditEntry("verify", 3, "refused", "v", "D", table_sha256=newer, bank=0))
    rc, out, err = station(capsys, "audit")
    assert rc == 0, err
    s = _summary(out)
    assert s[1].startswith(f"leg 1: {new[:12]} in bank 1, push ok ") and s[1].endswith(
        "failed: leg 1: push failed while writing bank 0: timeout. The previous table is still active; not verified since")
    assert s[2].endswith(f": completed PASS, but it found {newer[:12]} active: changed outside this log")
    assert s[3].startswith("leg 3: UNKNOWN: push ") and s[3].endswith(f": refused, found {newer[:12]} active (the new table)")
