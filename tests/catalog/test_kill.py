"""SIGKILL during catalog writes: afterwards `station catalog sync` indexes what the killed process
did not, and `station catalog check` reports nothing missing or inconsistent; the local SQLite
file is intact and the shared catalog holds what the local one holds."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import sqlalchemy as sa

from station.catalog import db, files, readers
from station.catalog.store import Catalog

WRITER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from station.catalog.store import Catalog
    from station.catalog.writer import register
    from tests.catalog.helpers import write_session
    runs = Path(sys.argv[1])
    cat = Catalog(local=runs / "catalog.sqlite", url=sys.argv[2], station_id="ST-K", connect_timeout_s=1)
    write_session(runs / "cal.h5", {1: "HX-K"})
    from station.catalog import readers
    cat.ingest([readers.session_rec(runs / "cal.h5")])
    i = 0
    while True:  # a table a few ms: the kill lands in a write sooner or later
        path = runs / f"t{i:05d}.csv"
        path.write_text("leg,position_mm,error_fwd_um,error_rev_um\\n" + f"1,0,{i / 1000},0\\n1,1,0,0\\n")
        register(cat, path, "table")
        print(i, flush=True)
        i += 1
""")


def test_sigkill_during_catalog_writes_then_sync_then_check(tmp_path, pg_url):
    runs = tmp_path / "runs"
    runs.mkdir()
    env = {**os.environ, "STATION_CATALOG": "on"}
    child = subprocess.Popen([sys.executable, "-c", WRITER, str(runs), pg_url], stdout=subprocess.PIPE, text=True,
                             env=env, cwd=os.getcwd())
    seen = 0
    deadline = time.monotonic() + 60
    while seen < 40 and time.monotonic() < deadline:  # some writes done, forwarded ones among them
        if child.stdout.readline() == "":
            break
        seen += 1
    os.kill(child.pid, signal.SIGKILL)
    child.wait(timeout=10)
    assert seen >= 40, "the writer did not get going"
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[station]\nrecordings_dir = "{runs}"\nid = "ST-K"\n[catalog]\nurl = "{pg_url}"\n')
    run = lambda *a: subprocess.run([sys.executable, "-m", "station.cli", *a], capture_output=True, text=True,  # noqa: E731
                                    env=env, timeout=120)
    synced = run("catalog", "sync", "--config", str(cfg))
    assert synced.returncode == 0, synced.stderr
    checked = run("catalog", "check", "--config", str(cfg))
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert "every file indexed and unchanged" in checked.stdout and "not yet forwarded" not in checked.stdout
    local = Catalog(local=runs / "catalog.sqlite")
    with local.engine.connect() as conn:
        assert conn.execute(sa.text("PRAGMA integrity_check")).scalar_one() == "ok"
    tables = sorted(runs.glob("t*.csv"))
    assert len(tables) >= seen
    assert files.check(local, [runs]).ok
    shared = db.open_engine(pg_url)
    assert files.records_json(shared) == files.records_json(local.engine)
    # the file being written when the kill came may be cut short (not a table at all): every
    # file that reads as a table is in both catalogs, once
    readable = sum(readers.table_rec(p) is not None for p in tables)
    assert readable >= len(tables) - 1
    assert sum(r["kind"] == "table" for r in files.records_json(shared)) == readable
    shared.dispose()
