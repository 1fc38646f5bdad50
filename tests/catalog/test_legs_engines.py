"""`legs` and `history` give the same answers on SQLite and PostgreSQL (the leg list is written
per engine: LATERAL joins on PostgreSQL, scalar subqueries on SQLite)."""

from __future__ import annotations

import dataclasses

from station.catalog import db, files
from station.catalog.history import history, legs
from station.catalog.store import Catalog, write_recs
from tests.catalog.helpers import write_session


def test_same_answers_on_both_engines(tmp_path, pg_url):
    runs = tmp_path / "runs"
    runs.mkdir()
    write_session(runs / "a1.h5", {1: "HX-1", 2: "HX-2"}, station="ST-A", started_utc="2026-01-05T08:00:00Z", seed=1)
    write_session(runs / "b1.h5", {1: "HX-1"}, station="ST-B", started_utc="2026-03-05T08:00:00Z", seed=2)
    write_session(runs / "a2.h5", {3: "HX-3"}, station="ST-A", started_utc="2026-06-05T08:00:00Z", seed=3,
                  leg_type="HX-L450")
    local = Catalog(local=runs / "catalog.sqlite", station_id="ST-A")
    files.index(local, [runs])
    from station.catalog.readers import session_rec

    shared = db.open_engine(pg_url)
    with shared.begin() as conn:
        write_recs(conn, [session_rec(p) for p in sorted(runs.glob("*.h5"))], "ST-A", queue=False)
    queries = [{}, {"leg_type": "HX-L450"}, {"station": "ST-B"}, {"since": "2026-02-01"}, {"until": "2026-03-05"},
               {"due_by": "2026-12-01", "interval_days": 300}]
    for kw in queries:
        a = [dataclasses.asdict(x) for x in legs(local.engine, **kw)]
        b = [dataclasses.asdict(x) for x in legs(shared, **kw)]
        assert a == b, kw
    assert [x.serial for x in legs(shared, station="ST-B")] == ["HX-1"]
    assert [x.serial for x in legs(shared, due_by="2026-12-01", interval_days=300)] == ["HX-2"]
    assert history(local.engine, "HX-1").to_json() == history(shared, "HX-1").to_json()
    # the fleet twin's query (station diagnose --twin fleet:TYPE)
    from station.catalog.fleet import completed_sessions_of_type

    for t in ("HX-L300", "HX-L450"):
        assert completed_sessions_of_type(local.engine, t) == completed_sessions_of_type(shared, t)
    assert [(r.serial, r.leg) for r in completed_sessions_of_type(shared, "HX-L300")] == [
        ("HX-1", 1), ("HX-2", 2), ("HX-1", 1)]
    shared.dispose()
