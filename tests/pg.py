"""A throwaway PostgreSQL cluster for tests: initdb + pg_ctl in a temporary folder, listening on a
unix socket only. As root (initdb refuses root) it runs as the `postgres` user on a folder that
user owns. `pg_cluster` (session-scoped) skips, naming why, when PostgreSQL is not installed,
except under CI=true, where .ci/run installs it and a missing server is a failure.
"""

from __future__ import annotations

import contextlib
import os
import pwd
import shutil
import subprocess
import tempfile
import uuid
from pathlib import Path

import pytest

BIN_DIRS = sorted(Path("/usr/lib/postgresql").glob("*/bin"), reverse=True)


def _tool(name: str) -> str | None:
    for d in BIN_DIRS:
        if (d / name).is_file():
            return str(d / name)
    return shutil.which(name)


class PgCluster:
    """A running cluster; `url(db)` for SQLAlchemy, `new_database()` a fresh database,
    `stop()` / `start()` to take the server away and bring it back."""

    def __init__(self, root: Path, run_as: str | None) -> None:
        self.root = root
        self.data = root / "data"
        self.run_as = run_as
        self.user = "station"

    def _cmd(self, *args: str) -> list[str]:
        return (["runuser", "-u", self.run_as, "--"] if self.run_as else []) + list(args)

    def _run(self, *args: str) -> None:
        out = subprocess.run(self._cmd(*args), capture_output=True, text=True, timeout=60)
        if out.returncode:
            raise RuntimeError(f"{' '.join(args)}: {out.stderr.strip() or out.stdout.strip()}")

    def init(self) -> None:
        self._run(_tool("initdb"), "-D", str(self.data), "-A", "trust", "-U", self.user, "--no-sync", "-E", "UTF8")
        with open(self.data / "postgresql.conf", "a") as fh:
            fh.write(f"\nlisten_addresses = ''\nunix_socket_directories = '{self.root}'\nfsync = off\n"
                     "max_connections = 50\n")

    def start(self) -> None:
        self._run(_tool("pg_ctl"), "-D", str(self.data), "-l", str(self.root / "log"), "-w", "start")

    def stop(self) -> None:
        self._run(_tool("pg_ctl"), "-D", str(self.data), "-m", "fast", "-w", "stop")

    def url(self, database: str = "postgres") -> str:
        return f"postgresql://{self.user}@/{database}?host={self.root}"

    def new_database(self) -> str:
        """A fresh, empty database; its URL."""
        import psycopg

        name = f"t_{uuid.uuid4().hex[:12]}"
        with psycopg.connect(f"host={self.root} user={self.user} dbname=postgres", autocommit=True) as conn:
            conn.execute(f"CREATE DATABASE {name}")
        return self.url(name)


def start_cluster() -> PgCluster:
    """Start a cluster (the caller stops it); pytest.skip/fail when PostgreSQL is not installed."""
    if _tool("initdb") is None or _tool("pg_ctl") is None:
        reason = "PostgreSQL (initdb, pg_ctl) is not installed: apt-get install postgresql"
        if os.environ.get("CI") == "true":
            pytest.fail(reason)
        pytest.skip(reason)
    run_as = None
    root = Path(tempfile.mkdtemp(prefix="station-pg-"))
    if os.geteuid() == 0:
        try:
            pw = pwd.getpwnam("postgres")
        except KeyError:
            shutil.rmtree(root, ignore_errors=True)
            reason = "running as root and there is no `postgres` user to run initdb as"
            if os.environ.get("CI") == "true":
                pytest.fail(reason)
            pytest.skip(reason)
        os.chown(root, pw.pw_uid, pw.pw_gid)
        run_as = "postgres"
    cluster = PgCluster(root, run_as)
    cluster.init()
    cluster.start()
    return cluster


def remove(cluster: PgCluster) -> None:
    try:
        cluster.stop()
    except Exception:
        pass
    shutil.rmtree(cluster.root, ignore_errors=True)


@contextlib.contextmanager
def bench_engine(ingest_recs, legs: int, calibrations: int, fill):
    """For the benches: a throwaway cluster's new database, filled by `fill(ingest, legs,
    calibrations)` through `ingest_recs(conn, recs)` and ANALYZEd (the planner's statistics, as
    autovacuum would keep them); yields its URL, or None (said on stdout) when PostgreSQL is not
    installed. The cluster is removed afterwards."""
    from station.catalog import db

    try:
        cluster = start_cluster()
    except BaseException as exc:  # pytest.skip outside pytest: PostgreSQL not installed
        print(f"PostgreSQL: not measured ({exc})")
        yield None
        return
    try:
        url = cluster.new_database()
        engine = db.open_engine(url)

        def ingest(recs):
            with engine.begin() as conn:
                ingest_recs(conn, recs)

        fill(ingest, legs, calibrations)
        with engine.connect() as conn:
            conn.execution_options(isolation_level="AUTOCOMMIT").exec_driver_sql("ANALYZE")
        engine.dispose()
        yield url
    finally:
        remove(cluster)
