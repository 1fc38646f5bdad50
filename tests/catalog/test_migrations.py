"""Alembic migrations of the catalog on SQLite and PostgreSQL: from empty and from the previous
revision, data kept; a catalog from a newer schema refused in one line."""

from __future__ import annotations

import pytest
import sqlalchemy as sa

from procedures.engine.errors import InputError
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
        assert db.current_revision(conn) == db.head_revision() == "0002"
    assert {"stations", "legs", "instruments", "records", "record_legs", "outbox"} <= set(sa.inspect(engine).get_table_names())
    assert "verification_ratio" in _columns(engine, "record_legs")
    indexes = {i["name"] for i in sa.inspect(engine).get_indexes("record_legs")}
    assert {"ix_record_legs_serial_time", "ix_record_legs_calibrations"} <= indexes
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
        assert db.current_revision(conn) == "0002"
        row = conn.execute(sa.text("SELECT leg_serial, \"E_um\", verification_ratio, outcome FROM record_legs")).one()
    assert tuple(row) == ("HX-1", 2.5, None, "completed")  # the outcome filled in from the record
    engine.dispose()


def test_newer_schema_refused_in_one_line(url, tmp_path):
    engine = db.open_engine(url)
    with engine.begin() as conn:
        conn.execute(sa.text("UPDATE alembic_version SET version_num = '0099'"))
    engine.dispose()
    with pytest.raises(InputError) as info:
        db.open_engine(url)
    message = str(info.value)
    assert "\n" not in message and "'0099'" in message and "'0002'" in message and "newer" in message


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
    assert len(err) == 1 and "abc123" in err[0] and "knows up to '0002'" in err[0]
