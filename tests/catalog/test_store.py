"""The catalog on real files: idempotent ingestion, forwarding to a real PostgreSQL that goes away
and comes back, rebuild equal to what was written live, check finding missing, changed and
unindexed files, history and leg lists."""

from __future__ import annotations

import json
import os

import pytest
import sqlalchemy as sa

from procedures.compensation.audit import AuditEntry, AuditLog
from station.catalog import db, files, history
from station.catalog.store import Catalog
from station.cli import main
from tests.catalog.helpers import write_session


def _count(engine, table="records"):
    with engine.connect() as conn:
        return conn.execute(sa.text(f"SELECT count(*) FROM {table}")).scalar_one()


def _comparable(engine):
    return [{k: v for k, v in r.items()} for r in files.records_json(engine)]


@pytest.fixture
def runs(tmp_path):
    d = tmp_path / "runs"
    d.mkdir()
    write_session(d / "cal1.h5", {1: "HX-1", 2: "HX-2"}, started_utc="2026-01-10T08:00:00.000000Z", seed=1)
    write_session(d / "cal2.h5", {1: "HX-1"}, started_utc="2026-04-11T09:30:00.000000Z", seed=2)
    write_session(d / "old.h5", None, started_utc="2025-12-01T08:00:00.000000Z", seed=3)  # a 1.0 file
    log = AuditLog(d / "audit.jsonl", operator="jdoe")
    for outcome in ("started", "ok"):
        entry = log.append(AuditEntry(action="push", leg=1, outcome=outcome, drive="Sim SD s/n D1", table_sha256="ab" * 32,
                                      bank=1, op_id="op1", source={"path": "t.csv", "sha256": "cd" * 32}))
    # the identity code adds leg_serial and station_id to entries: as it will write them
    lines = (d / "audit.jsonl").read_text().splitlines()
    last = json.loads(lines[-1])
    assert last["id"] == entry.id
    lines[-1] = json.dumps({**last, "leg_serial": "HX-1", "station_id": "ST-A"})
    (d / "audit.jsonl").write_text("\n".join(lines) + "\n")
    return d


def test_ingest_twice_is_once_and_keeps_file_times(runs):
    cat = Catalog(local=runs / "catalog.sqlite", station_id="ST-A")
    n1, problems = files.index(cat, [runs])
    n2, _ = files.index(cat, [runs])
    # 3 sessions + 2 audit entries; the second pass reads and queues nothing it indexed already
    assert problems == [] and n1 == 5 and n2 == 0
    assert _count(cat.engine) == 5
    times = dict(cat.engine.connect().execute(sa.text("SELECT path, time_utc FROM records WHERE kind='session'")).all())
    assert times[str((runs / "cal2.h5").resolve())] == "2026-04-11T09:30:00.000000Z"
    with cat.engine.connect() as conn:
        unknown = conn.execute(sa.text("SELECT leg_serial FROM record_legs WHERE uid IN "
                                       "(SELECT uid FROM records WHERE path LIKE '%old.h5')")).all()
        stations = dict(conn.execute(sa.text("SELECT path, station_id FROM records WHERE kind='session'")).all())
    assert unknown == [(None,)]  # 1.0 file: indexed, serial unknown
    assert stations[str((runs / "old.h5").resolve())] == "ST-A"  # no identity: the indexing station
    assert stations[str((runs / "cal1.h5").resolve())] == "ST-A"


def test_history_drift_and_due(runs):
    cat = Catalog(local=runs / "catalog.sqlite", station_id="ST-A")
    files.index(cat, [runs])
    h = history.history(cat.engine, "HX-1", interval_days=180)
    cals = h.calibrations
    assert [r.time_utc[:10] for r in cals] == ["2026-01-10", "2026-04-11"]
    e0, e1 = cals[0].figures["E"]["value_um"], cals[1].figures["E"]["value_um"]
    assert cals[0].figures["E"]["U_um"] > 0
    months = (91 + 1.5 / 24) / history.MONTH_DAYS
    assert h.drift[0].months == pytest.approx(months)
    assert h.drift[0].um_per_month["E"] == pytest.approx((e1 - e0) / months)
    assert h.due == "2026-10-08"
    rows = history.legs(cat.engine, interval_days=180)
    assert [(r.serial, r.calibrations) for r in rows] == [("HX-1", 2), ("HX-2", 1)]
    assert [r.serial for r in history.legs(cat.engine, due_by="2026-07-15", interval_days=180)] == ["HX-2"]
    assert [r.serial for r in history.legs(cat.engine, since="2026-02-01")] == ["HX-1"]
    assert [r.serial for r in history.legs(cat.engine, until="2026-01-10")] == ["HX-2"]
    assert history.legs(cat.engine, leg_type="other") == [] and history.legs(cat.engine, station="ST-B") == []


def test_check_lists_missing_changed_and_unindexed(runs):
    cat = Catalog(local=runs / "catalog.sqlite", station_id="ST-A")
    files.index(cat, [runs])
    assert files.check(cat, [runs]).ok
    (runs / "old.h5").unlink()
    with open(runs / "cal2.h5", "ab") as fh:
        fh.write(b"\0")
    write_session(runs / "new.h5", {3: "HX-3"}, seed=4)
    r = files.check(cat, [runs])
    assert [m.split()[0] for m in r.missing] == ["session"] and "old.h5" in r.missing[0]
    assert len(r.changed) == 1 and "cal2.h5" in r.changed[0]
    assert any("new.h5" in u for u in r.unregistered)


def test_rebuild_equals_live_index(runs, tmp_path):
    live = Catalog(local=runs / "catalog.sqlite", station_id="ST-A")
    files.index(live, [runs])
    rebuilt = Catalog(local=tmp_path / "rebuilt.sqlite", station_id="ST-A")
    files.rebuild(rebuilt, [runs])
    assert _comparable(live.engine) == _comparable(rebuilt.engine)


def test_forward_survives_server_away_and_back(runs, pg_cluster, pg_url):
    cat = Catalog(local=runs / "catalog.sqlite", url=pg_url, station_id="ST-A", connect_timeout_s=1)
    pg_cluster.stop()
    try:
        import time

        t0 = time.monotonic()
        files.index(cat, [runs])
        assert time.monotonic() - t0 < 10  # never waits on the dead server
        assert cat.last_forward.error and cat.backlog() == 5
    finally:
        pg_cluster.start()
    result = cat.forward(force=True)
    assert result.error == "" and result.forwarded == 5 and cat.backlog() == 0
    shared = db.open_engine(pg_url)
    assert _comparable(shared) == _comparable(cat.engine)  # original times and all
    # forwarding again (a rebuilt local catalog queues everything again) adds nothing
    files.rebuild(cat, [runs])
    assert cat.backlog() == 5
    assert cat.forward(force=True).forwarded == 5
    assert _count(shared) == 5 and _count(shared, "record_legs") == 6
    shared.dispose()


def test_commands_history_legs_check_json(runs, tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[station]\nrecordings_dir = "{runs}"\nid = "ST-A"\n[catalog]\ncalibration_interval_days = 30\n')
    assert main(["catalog", "sync", "--config", str(cfg)]) == 0
    capsys.readouterr()
    assert main(["history", "HX-1", "--config", str(cfg), "--json"]) == 0
    h = json.loads(capsys.readouterr().out)
    assert h["serial"] == "HX-1" and len(h["rows"]) == 3 and h["due"] == "2026-05-11"  # 2 sessions + the push
    assert main(["legs", "--config", str(cfg), "--json", "--due", "2026-03-01"]) == 0
    assert [r["serial"] for r in json.loads(capsys.readouterr().out)] == ["HX-2"]
    assert main(["catalog", "check", "--config", str(cfg)]) == 0
    os.remove(runs / "cal1.h5")
    assert main(["catalog", "check", "--config", str(cfg)]) == 1
    assert "missing: session" in capsys.readouterr().out
    assert main(["history", "NOPE", "--config", str(cfg)]) == 2  # an unknown serial: one line, as legs --type NOPE
    assert "NOPE: no records of a leg with this serial in the catalog" in capsys.readouterr().err


def test_an_unwritable_catalog_never_fails_the_work(runs, tmp_path, caplog):
    """The sink and `register` log and go on when the catalog cannot be written (here its folder
    is a file); `catalog sync` indexes the files later."""
    from station.catalog.writer import CatalogSink, register

    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")
    cat = Catalog(local=blocker / "catalog.sqlite", station_id="ST-A")
    sink = CatalogSink(cat, runs / "cal1.h5")
    sink.close("completed")
    sink.thread.join(60)
    assert register(cat, runs / "cal1.h5", "model") == []
    assert sink.uids == [] and "not indexed" in caplog.text
    good = Catalog(local=runs / "catalog.sqlite", station_id="ST-A")
    sink = CatalogSink(good, runs / "cal1.h5")
    sink.close("completed")
    sink.thread.join(60)
    assert len(sink.uids) == 1 and sink.uids[0].startswith("session:")


def test_instrument_from_identity_or_the_configs_metrology(runs):
    """A 1.1 session names its instrument in /meta identity; a 1.0 session in its recorded config."""
    from procedures.io.recording.writer import SessionWriter
    from station.catalog import readers
    from tests.tooling import default_legs_points

    assert readers.session_rec(runs / "cal1.h5").instrument["serial"] == "LZ-1"
    path = runs / "metrology.h5"
    with SessionWriter.create(path, session_id="m", operator="t", rig="sim", plan={"kind": "test"},
                              station_config={"metrology": {"serial": "123", "model": "XL-80",
                                                            "calibration_date": "2026-03-01"}},
                              devices={}, software_version="t") as w:
        w.append_points(default_legs_points([1], 2, 15.0, 0))
        w.finish("completed")
    assert readers.session_rec(path).instrument == {"serial": "123", "model": "XL-80", "calibration_due": None,
                                                    "calibrated_on": "2026-03-01"}
    assert readers.session_rec(runs / "old.h5").instrument is None
