"""Acceptance: two station processes (two configs, two station ids) sweep, fit, make a table and
push it against one real PostgreSQL that is stopped in the middle and started again. Afterwards
the shared catalog holds every record exactly once, with its original time, and equals the
`station catalog rebuild` of both stations' files."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import sqlalchemy as sa

from station.catalog import db, files

STATION = [sys.executable, "-m", "station.cli"]


def _station(*args: str) -> float:
    """Run `station ARGS`; seconds it took. Fails the test on a non-zero exit."""
    env = {**os.environ, "STATION_CATALOG": "on"}
    t0 = time.monotonic()
    out = subprocess.run([*STATION, *args], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, f"station {' '.join(args)}: {out.stderr.strip()}"
    return time.monotonic() - t0


def _config(tmp: Path, name: str, seed: int, url: str) -> Path:
    runs = tmp / name
    runs.mkdir()
    cfg = tmp / f"{name}.toml"
    cfg.write_text(f'[station]\nrecordings_dir = "{runs}"\nid = "ST-{name.upper()}"\n[drive]\nurl = "sim"\n[interferometer]\nport = "sim"\n'
                   f'[sim]\nseed = {seed}\n[catalog]\nurl = "{url}"\nconnect_timeout_s = 1\n')
    return cfg


def _sweep(cfg: Path, out: Path, *extra: str) -> float:
    return _station("sweep", "--config", str(cfg), "--out", str(out), "--legs", "1", "--cycles", "2",
                    "--n-targets", "5", "--dwell", "0.1", *extra)


def _parallel(*jobs) -> list:
    results: list = [None] * len(jobs)
    errors: list = []

    def work(i, fn):
        try:
            results[i] = fn()
        except BaseException as exc:  # reported in the main thread
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(i, fn)) for i, fn in enumerate(jobs)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors:
        raise errors[0]
    return results


def test_two_stations_one_shared_catalog_through_an_outage(tmp_path, pg_cluster, pg_url):
    cfgs = {name: _config(tmp_path, name, seed, pg_url) for name, seed in (("a", 1), ("b", 2))}
    runs = {name: tmp_path / name for name in cfgs}

    def first_half(name):
        cfg, d = cfgs[name], runs[name]
        _sweep(cfg, d / "cal.h5")
        _station("fit", str(d / "cal.h5"), "--out", str(d / "model.json"), "--config", str(cfg))

    def second_half(name):
        cfg, d = cfgs[name], runs[name]
        took = [_station("table", str(d / "model.json"), "--out", str(d / "table.csv"), "--config", str(cfg)),
                _station("push", str(d / "table.csv"), "--leg", "1", "--config", str(cfg), "--yes")]
        return max(took)

    _parallel(lambda: first_half("a"), lambda: first_half("b"))  # both stations write at once
    shared = db.open_engine(pg_url)
    with shared.connect() as conn:
        before_outage = conn.execute(sa.text("SELECT count(*) FROM records")).scalar_one()
    assert before_outage == 4  # two sessions, two models, forwarded as they were written
    pg_cluster.stop()
    try:
        slowest = max(_parallel(lambda: second_half("a"), lambda: second_half("b")))
        assert slowest < 30  # the dead server never held a station up
    finally:
        pg_cluster.start()
    # the next write forwards the backlog by itself; `catalog sync` catches up the rest
    _sweep(cfgs["a"], runs["a"] / "after.h5", "--yes")  # leg 1 has station a's table now: a compensated sweep
    for name in cfgs:
        _station("catalog", "sync", "--config", str(cfgs[name]))

    shared = db.open_engine(pg_url)
    in_shared = files.records_json(shared)
    uids = [r["uid"] for r in in_shared]
    assert len(uids) == len(set(uids))
    kinds = sorted(r["kind"] for r in in_shared)
    # per station: session, model, table, push started + ok; station a: one more session
    assert kinds == sorted(["session"] * 3 + ["model"] * 2 + ["table"] * 2 + ["push"] * 4)
    assert {r["station_id"] for r in in_shared} == {"ST-A", "ST-B"}

    rebuilt = []
    for name in cfgs:
        db_file = tmp_path / f"rebuilt-{name}.sqlite"
        _station("catalog", "rebuild", str(runs[name]), "--config", str(cfgs[name]), "--db", str(db_file))
        engine = db.open_engine(db.sqlite_url(db_file))
        rebuilt += files.records_json(engine)
        engine.dispose()
    assert sorted(rebuilt, key=lambda r: r["uid"]) == in_shared  # same records, same original times
    # the sessions' times are the files' own start times
    import h5py

    for r in in_shared:
        if r["kind"] == "session":
            with h5py.File(r["path"], "r") as f:
                assert r["time_utc"] == f.attrs["started_utc"]
    shared.dispose()
