"""Several processes of one station opening (and so creating) one new local catalog at once:
each gets it, migrated once (SQLite runs DDL outside transactions; a lock file serialises it)."""

from __future__ import annotations

import os
import subprocess
import sys

import sqlalchemy as sa

from station.catalog import db

OPEN = ("import sys; from pathlib import Path; from station.catalog.store import Catalog; "
        "c = Catalog(local=Path(sys.argv[1])); print(c.backlog())")


def test_processes_creating_one_catalog_at_once(tmp_path):
    for round_ in range(3):
        path = tmp_path / f"r{round_}" / "catalog.sqlite"
        path.parent.mkdir()
        procs = [subprocess.Popen([sys.executable, "-c", OPEN, str(path)], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True, cwd=os.getcwd()) for _ in range(3)]
        outs = [(p.wait(timeout=120), *p.communicate()) for p in procs]
        assert [(code, out.strip()) for code, out, _ in outs] == [(0, "0")] * 3, [err for *_, err in outs]
        engine = db.open_engine(db.sqlite_url(path))
        with engine.connect() as conn:
            assert db.current_revision(conn) == db.head_revision()
            assert conn.execute(sa.text("SELECT count(*) FROM alembic_version")).scalar_one() == 1
        engine.dispose()
