"""The audit log: append-only JSON lines, one complete line per entry, readable after a crash."""

from __future__ import annotations

import json
import os
import threading

import pytest

from procedures.compensation.audit import AuditEntry, AuditError, AuditLog, read_entries


def _entry(i: int = 0, **kw) -> AuditEntry:
    base = dict(action="push", leg=1 + i % 6, outcome="ok", message=f"entry {i}", drive="Sim s/n 1",
                drive_url="tcp://127.0.0.1:1", table_sha256="ab" * 32, bank=1, previous_bank=0)
    base.update(kw)
    return AuditEntry(**base)


def test_entries_are_appended_as_json_lines_with_who_and_when(tmp_path):
    log = AuditLog(tmp_path / "sub" / "audit.jsonl", operator="jdoe")
    backup = {"bank": 0, "start_mm": -90.0, "spacing_mm": 1.0, "error_fwd_um": [0.1, 0.2],
              "error_rev_um": [-0.1, -0.2], "checksum": 1234, "sha256": "cd" * 32}
    written = log.append(_entry(backup=backup, details={"rms_um": 0.2}))
    assert written.operator == "jdoe" and written.id and written.host
    assert written.time_utc.endswith("Z") and written.time_utc[:4].isdigit() and "T" in written.time_utc
    lines = (tmp_path / "sub" / "audit.jsonl").read_text().splitlines()
    assert len(lines) == 1
    doc = json.loads(lines[0])
    assert doc["action"] == "push" and doc["leg"] == 1 and doc["outcome"] == "ok" and doc["v"] == 1
    assert doc["backup"]["error_fwd_um"] == [0.1, 0.2] and doc["details"] == {"rms_um": 0.2}
    entries, problems = log.read()
    assert problems == [] and entries == [written]


def test_appending_never_rewrites_what_is_there(tmp_path):
    path = tmp_path / "audit.jsonl"
    log = AuditLog(path)
    log.append(_entry(0))
    before = path.read_bytes()
    inode = os.stat(path).st_ino
    log.append(_entry(1, outcome="failed"))
    after = path.read_bytes()
    assert after.startswith(before) and after.count(b"\n") == 2
    assert os.stat(path).st_ino == inode, "the file was replaced, not appended to"


def test_a_line_cut_short_is_reported_and_the_next_entry_starts_on_its_own_line(tmp_path):
    path = tmp_path / "audit.jsonl"
    log = AuditLog(path)
    log.append(_entry(0))
    with open(path, "ab") as fh:  # a crash in the middle of a write
        fh.write(b'{"action": "push", "leg": 2, "outc')
    log.append(_entry(1))
    entries, problems = read_entries(path)
    assert [e.message for e in entries] == ["entry 0", "entry 1"]
    assert len(problems) == 1 and problems[0].line == 2 and "not an audit entry" in problems[0].reason


def test_last_finds_the_latest_matching_entry(tmp_path):
    log = AuditLog(tmp_path / "a.jsonl")
    log.append(_entry(0, leg=2, outcome="ok", message="first"))
    log.append(_entry(0, leg=2, outcome="failed", message="second"))
    log.append(_entry(0, leg=3, outcome="ok", message="other leg"))
    log.append(_entry(0, leg=2, outcome="ok", message="other drive", drive="Sim s/n 2"))
    assert log.last("push", 2, "Sim s/n 1").message == "first"
    assert log.last("push", 2, "Sim s/n 1", outcomes=("ok", "failed")).message == "second"
    assert log.last("rollback", 2, "Sim s/n 1") is None


def test_concurrent_appends_give_whole_lines(tmp_path):
    path = tmp_path / "audit.jsonl"
    big = {"error_fwd_um": [0.01 * i for i in range(512)], "error_rev_um": [-0.01 * i for i in range(512)]}

    def writer(k: int) -> None:
        log = AuditLog(path)  # each its own handle, as separate processes would have
        for i in range(25):
            log.append(_entry(k * 100 + i, backup=big))

    threads = [threading.Thread(target=writer, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    entries, problems = read_entries(path)
    assert problems == [] and len(entries) == 100
    assert sorted(e.message for e in entries) == sorted(f"entry {k * 100 + i}" for k in range(4) for i in range(25))


def test_a_directory_in_place_of_the_log_is_refused(tmp_path):
    (tmp_path / "audit.jsonl").mkdir()
    with pytest.raises(AuditError, match="audit.jsonl"):
        AuditLog(tmp_path / "audit.jsonl").append(_entry())


def test_unknown_action_is_a_programming_error(tmp_path):
    with pytest.raises(ValueError, match="unknown audit action"):
        AuditLog(tmp_path / "a.jsonl").append(_entry(action="erase"))
