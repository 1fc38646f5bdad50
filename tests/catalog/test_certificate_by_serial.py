"""`station certificate --serial`: the sessions and table found in the catalog (SQLite, and the
shared PostgreSQL catalog), the certificate issued from them as from the files, and the one-line
refusals (unknown serial, no calibration, a listed file missing on disk)."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from drivers.plant.leg import default_leg_configs
from procedures.compensation.audit import AuditEntry
from procedures.compensation.table import CompTable, LegTable, table_csv_text
from station.catalog.readers import audit_recs, session_rec, table_rec
from station.catalog.store import Catalog
from station.cli import main
from procedures.synthetic import synth_session
from tests.tooling import lab_config, write_identified_session

TOL = {"HX300": {"as_found_um": {"E": 25.0, "B": 6.0, "R": 3.0}, "as_left_um": {"E": 0.001}, "source": "recorded"}}
CAL, VER = {"kind": "iso230"}, {"kind": "verification"}


def _table(path, offset_um: float):
    rows = tuple(offset_um for _ in range(31))
    path.write_text(table_csv_text(CompTable({1: LegTable(1, -90.0, 6.0, rows, rows)})))
    return path


def _push(leg_serial: str, table, time_utc: str, n: int, outcome: str = "ok") -> dict:
    sha = hashlib.sha256(table.read_bytes()).hexdigest()
    return AuditEntry("push", 1, outcome, "pushed", drive="sim", id=f"push-{n}", time_utc=time_utc,
                      table_sha256=sha, source={"path": str(table), "leg": 1, "sha256": sha},
                      leg_serial=leg_serial, station_id="bench-1").to_json()


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """Sessions of three legs, two tables, an audit log, all indexed in an SQLite catalog."""
    d = tmp_path_factory.mktemp("fleet")
    targets = np.linspace(-90.0, 90.0, 11)
    pts = [synth_session({1: default_leg_configs(0)[0]}, targets, cycles=5, seed=s) for s in range(3)]
    left = pts[2].copy()
    left["error_um"] = 0.1 * (left["error_um"] - left["error_um"].mean())  # as if compensated
    cfg = {"tolerances": TOL}

    def session(name, points, plan, day, serial="HX-0042"):
        return write_identified_session(d / name, points, plan=plan, station_config=cfg, serial=serial,
                                        started_utc=f"2026-{day}T08:00:00.000000Z")

    files = {
        "cal_old": session("cal-jan.h5", pts[0], CAL, "01-10"),
        "ver_old": session("ver-feb.h5", left, VER, "02-01"),  # verifies the January calibration
        "cal": session("cal-mar.h5", pts[1], CAL, "03-01"),
        "ver": session("ver-mar.h5", left, VER, "03-02"),
        "ver_only": session("ver-77.h5", left, VER, "03-03", serial="HX-0077"),
        "lost": session("cal-55.h5", pts[0], CAL, "03-04", serial="HX-0055"),
        "old_table": _table(d / "table-jan.csv", 0.0),
        "table": _table(d / "table-mar.csv", 0.5),
    }
    log = d / "audit.jsonl"
    log.write_text("".join(json.dumps(e) + "\n" for e in (
        _push("HX-0042", files["old_table"], "2026-01-11T09:00:00Z", 1),
        _push("HX-0042", files["table"], "2026-03-01T12:00:00Z", 2),
        _push("HX-0042", files["old_table"], "2026-03-01T13:00:00Z", 3, outcome="failed"))))  # not active
    recs = [session_rec(files[k]) for k in ("cal_old", "ver_old", "cal", "ver", "ver_only", "lost")]
    recs += [table_rec(files["old_table"]), table_rec(files["table"]), *audit_recs(log)]
    catalog = Catalog(local=d / "catalog.sqlite", station_id="bench-1")
    catalog.ingest(recs)
    catalog.close()
    files["lost"].unlink()  # indexed, then gone from the disk
    return {"dir": d, "files": files, "recs": recs, "catalog": d / "catalog.sqlite"}


@pytest.fixture
def cfg(tmp_path):
    return lab_config(tmp_path)


def _certify(capsys, *argv):
    rc = main(["certificate", *map(str, argv)])
    out, err = capsys.readouterr()
    return rc, out, err


def _check_issued(fleet, out, tmp_path):
    f = fleet["files"]
    lines = out.splitlines()
    assert f"as found: {f['cal'].resolve()} (calibration session, 2026-03-01T08:00:00.000000Z" in out
    assert f"as left: {f['ver'].resolve()} (verification session, 2026-03-02T08:00:00.000000Z" in out
    assert f"table: {f['table'].resolve()} (last table pushed, 2026-03-01T12:00:00Z" in out
    # the choice is printed before the certificate is issued
    assert min(i for i, ln in enumerate(lines) if ln.startswith("as found:")) < \
        min(i for i, ln in enumerate(lines) if ln.startswith("certificate "))
    (issued,) = sorted((tmp_path / "runs" / "certificates").glob("*_r1.json"))
    c = json.loads(issued.read_text())
    day = c["issued_utc"][:10].replace("-", "")
    assert c["report_no"] == f"bench-1-{day}-0001" and issued.name == f"bench-1-{day}-0001_r1.json"
    assert c["item"]["serial"] == "HX-0042"
    assert c["as_found"]["session_sha256"] == hashlib.sha256(f["cal"].read_bytes()).hexdigest()
    assert c["as_left"]["session_sha256"] == hashlib.sha256(f["ver"].read_bytes()).hexdigest()
    assert c["compensation_table"]["sha256"] == hashlib.sha256(f["table"].read_bytes()).hexdigest()
    return c


def test_serial_picks_latest_calibration_later_verification_and_last_push(fleet, cfg, tmp_path, capsys):
    rc, out, err = _certify(capsys, "--serial", "HX-0042", "--catalog", fleet["catalog"], "--config", cfg)
    assert rc == 0, err
    c = _check_issued(fleet, out, tmp_path)
    # the same certificate content as the file-based path given the same files
    rc, out2, err = _certify(capsys, fleet["files"]["cal"], "--as-left", fleet["files"]["ver"],
                             "--table", fleet["files"]["table"], "--config", cfg)
    assert rc == 0, err
    (second_file,) = (tmp_path / "runs" / "certificates").glob("*-0002_r1.json")  # exactly the one meant
    second = json.loads(second_file.read_text())
    for key in ("item", "as_found", "as_left", "compensation_table", "instrument"):
        assert second[key] == c[key], key


def test_serial_without_later_verification_has_no_as_left(fleet, cfg, tmp_path, capsys):
    catalog = Catalog(local=tmp_path / "only-jan.sqlite", station_id="bench-1")
    files = fleet["files"]
    catalog.ingest([r for r in fleet["recs"] if r.path in (str(files["cal_old"].resolve()),)])
    catalog.close()
    rc, out, err = _certify(capsys, "--serial", "HX-0042", "--catalog", tmp_path / "only-jan.sqlite", "--config", cfg)
    assert rc == 0, err
    assert f"as found: {files['cal_old'].resolve()}" in out
    assert "as left: none (no verification session after the calibration)" in out
    assert "table: none" in out
    (issued,) = (tmp_path / "runs" / "certificates").glob("*_r1.json")
    c = json.loads(issued.read_text())
    assert c["as_left"] is None and c["compensation_table"] is None


@pytest.mark.parametrize("serial, message", [
    ("HX-9999", "no leg with serial 'HX-9999' in the catalog; `station legs` lists the serials it holds"),
    ("HX-0077", "leg HX-0077: the catalog holds no completed calibration session of it (`station history HX-0077`"),
    ("HX-0055", "cal-55.h5: the catalog lists this calibration session of leg HX-0055 but the file is missing; "
                "restore it, or re-index with `station catalog check` and `station catalog rebuild DIR`"),
])
def test_refusals_are_one_line(fleet, cfg, tmp_path, capsys, serial, message):
    rc, out, err = _certify(capsys, "--serial", serial, "--catalog", fleet["catalog"], "--config", cfg)
    assert rc == 2
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "runs" / "certificates").exists() or not any((tmp_path / "runs" / "certificates").iterdir())


def test_serial_and_session_are_exclusive(fleet, cfg, capsys):
    assert main(["certificate", str(fleet["files"]["cal"]), "--serial", "HX-0042", "--config", str(cfg)]) == 2
    assert "not allowed with argument" in capsys.readouterr().err


def test_serial_through_the_shared_postgresql_catalog(fleet, cfg, tmp_path, capsys, pg_url):
    catalog = Catalog(local=tmp_path / "local.sqlite", url=pg_url, station_id="bench-1")
    catalog.ingest(fleet["recs"])
    assert catalog.last_forward.error == "" and catalog.backlog() == 0
    catalog.close()
    rc, out, err = _certify(capsys, "--serial", "HX-0042", "--catalog", pg_url, "--config", cfg)
    assert rc == 0, err
    _check_issued(fleet, out, tmp_path)


def test_older_records_without_plan_kind_tell_verifications_by_their_audit_entry(fleet, cfg, tmp_path, capsys):
    """Records indexed before the plan kind was kept: a session a `station verify` entry names is the as left."""
    import dataclasses

    files = fleet["files"]
    wanted = {str(files[k].resolve()) for k in ("cal", "ver")}
    recs = [dataclasses.replace(r, summary={k: v for k, v in r.summary.items() if k != "plan_kind"})
            for r in fleet["recs"] if r.path in wanted]
    sha = hashlib.sha256(files["ver"].read_bytes()).hexdigest()
    log = tmp_path / "verify.jsonl"
    log.write_text(json.dumps(AuditEntry("verify", 1, "completed", "verified", id="verify-1", leg_serial="HX-0042",
                                         time_utc="2026-03-02T09:00:00Z",
                                         details={"session_sha256": sha}).to_json()) + "\n")
    catalog = Catalog(local=tmp_path / "legacy.sqlite", station_id="bench-1")
    catalog.ingest([*recs, *audit_recs(log)])
    catalog.close()
    rc, out, err = _certify(capsys, "--serial", "HX-0042", "--catalog", tmp_path / "legacy.sqlite", "--config", cfg)
    assert rc == 0, err
    # without the audit entry the later session would count as the latest calibration
    assert f"as found: {files['cal'].resolve()}" in out and f"as left: {files['ver'].resolve()}" in out
