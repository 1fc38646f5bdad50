"""Alembic migrations of the catalog on SQLite and PostgreSQL: from empty and from the previous
revision, data kept; a catalog from a newer schema refused in one line."""

from __future__ import annotations

import pytest
import sqlalchemy as sa

from procedures.vocabulary import InputError
from station.catalog import db
from station.cli import main


@pytest.fixture(params=["sqlite", "postgresql"])
def url(request, tmp_path):
    if request.param == "sqlite":
        return db.sqlite_url(tmp_path / "c.sqlite")
    return request.getfixturevalue("pg_url")


def _columns(engine, table):
    return {c["name"] for c in sa.inspect(engine).get_columns(table)}


def test_from_empty_to_head(url):
    engine = db.open_engine(url)
    with engine.connect() as conn:
        assert db.current_revision(conn) == db.head_revision() == "0005"
    assert {"stations", "legs", "instruments", "records", "record_legs", "outbox"} <= set(sa.inspect(engine).get_table_names())
    assert {"verification_ratio", "stage"} <= _columns(engine, "record_legs")
    assert {"stage", "supersedes"} <= _columns(engine, "records")
    indexes = {i["name"] for i in sa.inspect(engine).get_indexes("record_legs")}
    assert {"ix_record_legs_serial_time", "ix_record_legs_calibrations", "ix_record_legs_stage",
            "ix_record_legs_last"} <= indexes
    engine.dispose()


def test_from_previous_revision_keeps_rows(url):
    engine = db.make_engine(url)
    db.migrate(engine, "0001")
    assert "verification_ratio" not in _columns(engine, "record_legs")
    with engine.begin() as conn:
        conn.execute(sa.text("INSERT INTO records (uid, kind, time_utc, outcome) "
                             "VALUES ('session:x', 'session', '2026-01-01T00:00:00Z', 'completed')"))
        conn.execute(sa.text("INSERT INTO record_legs (uid, leg, kind, time_utc, leg_serial, \"E_um\") "
                             "VALUES ('session:x', 1, 'session', '2026-01-01T00:00:00Z', 'HX-1', 2.5)"))
    engine.dispose()
    engine = db.open_engine(url)  # opening migrates to head
    with engine.connect() as conn:
        assert db.current_revision(conn) == "0005"
        row = conn.execute(sa.text("SELECT leg_serial, \"E_um\", verification_ratio, outcome, stage FROM record_legs")).one()
    assert tuple(row) == ("HX-1", 2.5, None, "completed", "as_found")  # outcome and stage filled in from the record
    engine.dispose()


def test_0003_classifies_the_records_indexed_before(url):
    """Revision 0003 gives every record indexed before its stage from what the catalog holds: the
    plan kind a session's summary keeps, a verification entry naming a session, the audit kinds."""
    engine = db.make_engine(url)
    db.migrate(engine, "0002")
    rows = [("session:cal", "session", "c1", '{"plan_kind": "iso230"}'),
            ("session:ver", "session", "v1", '{"plan_kind": "verification"}'),
            ("session:old", "session", "v2", None),  # no plan kind kept, but a verification entry names it
            ("session:imp", "session", "i1", '{"plan_kind": "import"}'),
            ("verification:e1", "verification", "v2", None),
            ("push:p1", "push", "t1", None), ("rollback:r1", "rollback", "t1", None), ("model:m", "model", "m1", None)]
    with engine.begin() as conn:
        for uid, kind, sha, summary in rows:
            conn.execute(sa.text("INSERT INTO records (uid, kind, time_utc, outcome, sha256, summary) "
                                 "VALUES (:u, :k, '2026-01-01T00:00:00Z', 'completed', :s, :m)"),
                         {"u": uid, "k": kind, "s": sha, "m": summary})
            conn.execute(sa.text("INSERT INTO record_legs (uid, leg, kind, time_utc, leg_serial) "
                                 "VALUES (:u, 1, :k, '2026-01-01T00:00:00Z', 'HX-1')"), {"u": uid, "k": kind})
    engine.dispose()
    engine = db.open_engine(url)
    with engine.connect() as conn:
        stages = dict(conn.execute(sa.text("SELECT uid, stage FROM records")).all())
        leg_stages = dict(conn.execute(sa.text("SELECT uid, stage FROM record_legs")).all())
    assert stages == {"session:cal": "as_found", "session:ver": "as_left", "session:old": "as_left",
                      "session:imp": "other", "verification:e1": "as_left", "push:p1": "adjustment",
                      "rollback:r1": "adjustment", "model:m": None}
    assert leg_stages == stages  # copied to the leg rows
    engine.dispose()


def test_newer_schema_refused_in_one_line(url, tmp_path):
    engine = db.open_engine(url)
    with engine.begin() as conn:
        conn.execute(sa.text("UPDATE alembic_version SET version_num = '0099'"))
    engine.dispose()
    with pytest.raises(InputError) as info:
        db.open_engine(url)
    message = str(info.value)
    assert "\n" not in message and "'0099'" in message and "'0005'" in message and "newer" in message


def test_newer_local_catalog_refused_by_the_command(tmp_path, capsys):
    runs = tmp_path / "runs"
    engine = db.open_engine(db.sqlite_url(runs / "catalog.sqlite"))
    with engine.begin() as conn:
        conn.execute(sa.text("UPDATE alembic_version SET version_num = 'abc123'"))
    engine.dispose()
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[station]\nrecordings_dir = "{runs}"\n')
    assert main(["catalog", "status", "--config", str(cfg)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "abc123" in err[0] and "knows up to '0005'" in err[0]
