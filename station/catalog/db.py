"""Opening a catalog: an SQLAlchemy engine for a URL (SQLite file or PostgreSQL through psycopg 3),
brought to this station's schema revision by Alembic, or refused in one line when it was written
by a newer station (an Alembic revision this one does not know).

SQLite: WAL and a busy timeout, so several processes of one station can write at once.
PostgreSQL: a short connect timeout (`connect_timeout_s`), so an unreachable server costs a
moment, never a hang; migrations run under an advisory lock, so two stations starting at once
do not both create the tables.
"""

from __future__ import annotations

import fcntl
import threading
from pathlib import Path

import sqlalchemy as sa
from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import event
from sqlalchemy.engine import Engine

from procedures.vocabulary import InputError

MIGRATIONS = Path(__file__).with_name("migrations")
# Alembic's `context`/`op` are module-level proxies set and removed around each run: two threads
# migrating at once (a job opening its local catalog while the backlog thread opens the shared
# one) tear them down under each other (KeyError 'config'). One migration per process at a time.
_MIGRATING = threading.Lock()
_LOCK_KEY = 230_2023  # advisory lock id for migrations on PostgreSQL


class CatalogVersionError(InputError):
    """The catalog was written by a newer station (unknown schema revision)."""


class CatalogUnreachable(Exception):
    """The shared catalog's server did not answer (the record stays in the local backlog)."""


def alembic_config() -> Config:
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    return cfg


def head_revision() -> str:
    return ScriptDirectory.from_config(alembic_config()).get_current_head()


def known_revisions() -> set[str]:
    return {s.revision for s in ScriptDirectory.from_config(alembic_config()).walk_revisions()}


def sqlite_url(path: str | Path) -> str:
    return f"sqlite:///{Path(path)}"


def describe(url: str) -> str:
    """The URL without a password (for messages)."""
    try:
        return sa.engine.make_url(url).render_as_string(hide_password=True)
    except Exception:
        return url


def make_engine(url: str, connect_timeout_s: float = 2.0, statement_timeout_s: float = 5.0) -> Engine:
    """An engine for `url` (postgresql:// is taken as psycopg 3). InputError for a URL that is
    neither SQLite nor PostgreSQL. On PostgreSQL every statement of every connection ends after
    `statement_timeout_s`, and so does its wait for a lock another session holds (lock_timeout:
    a `LOCK TABLE records` elsewhere costs a station's write at most that, then the record waits
    in the outbox); only connecting has its own `connect_timeout_s`."""
    try:
        u = sa.engine.make_url(url)
    except Exception:
        raise InputError(f"[catalog] url = {url!r}: not a database URL (e.g. postgresql://user@host/db)") from None
    if u.get_backend_name() == "sqlite":
        if u.database and u.database != ":memory:":
            Path(u.database).parent.mkdir(parents=True, exist_ok=True)
        engine = sa.create_engine(u, connect_args={"timeout": 30})

        @event.listens_for(engine, "connect")
        def _pragmas(dbapi_conn, _record):  # pragma: no cover - trivial
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA busy_timeout=30000")
            cur.execute("PRAGMA foreign_keys=ON")
            cur.close()

        return engine
    if u.get_backend_name() == "postgresql":
        u = u.set(drivername="postgresql+psycopg")
        ms = max(1, int(round(statement_timeout_s * 1000)))
        # the lock wait ends a little before the statement would: the error then names the lock
        lock_ms = max(1, int(ms * 0.8))
        return sa.create_engine(u, connect_args={"connect_timeout": max(1, int(round(connect_timeout_s))),
                                                 "options": f"-c statement_timeout={ms} -c lock_timeout={lock_ms}"},
                                pool_pre_ping=True)
    raise InputError(f"[catalog] url = {describe(url)!r}: only sqlite:/// and postgresql:// catalogs are supported")


def current_revision(conn: sa.Connection) -> str | None:
    return MigrationContext.configure(conn).get_current_revision()


def migrate(engine: Engine, revision: str = "head") -> None:
    """Bring the catalog at `engine` to `revision` (default: this station's head). Refused with
    CatalogVersionError when it carries a revision this station does not know (a newer schema)."""
    with engine.begin() as conn:
        if conn.dialect.name == "postgresql":
            conn.execute(sa.text("SELECT pg_advisory_xact_lock(:k)"), {"k": _LOCK_KEY})
        found = current_revision(conn)
        if found is not None and found not in known_revisions():
            raise CatalogVersionError(
                f"catalog {describe(str(engine.url))}: schema revision {found!r} was written by a newer station "
                f"(this one knows up to {head_revision()!r}); update the station software to the version that "
                f"wrote it, or point [catalog] url at another catalog")
        if conn.dialect.name == "postgresql" and found != head_revision():
            # a migration may rewrite every row (0003 classifies them): not bounded by the statement
            # timeout of ordinary writes; a lock another session holds is still waited for at most
            # lock_timeout
            conn.execute(sa.text("SET LOCAL statement_timeout = 0"))
        cfg = alembic_config()
        cfg.attributes["connection"] = conn
        with _MIGRATING:
            command.upgrade(cfg, revision)


def open_engine(url: str, connect_timeout_s: float = 2.0, statement_timeout_s: float = 5.0) -> Engine:
    """An engine for `url`, migrated to head. CatalogUnreachable when a server does not answer
    (or, PostgreSQL, does not answer within `statement_timeout_s`, e.g. a lock held elsewhere)."""
    engine = make_engine(url, connect_timeout_s, statement_timeout_s)
    try:
        database = engine.url.database if engine.dialect.name == "sqlite" else None
        if database and database != ":memory:":
            # SQLite runs DDL outside a transaction: two processes creating one new catalog at once
            # would both create its tables; a lock file beside it lets one migrate at a time
            try:
                lock = open(f"{database}.lock", "a")
            except OSError as exc:
                raise InputError(f"catalog {database}: cannot create it ({exc.strerror or exc}); check "
                                 "[station] recordings_dir") from None
            with lock:
                fcntl.flock(lock, fcntl.LOCK_EX)
                migrate(engine)
        else:
            migrate(engine)
    except sa.exc.OperationalError as exc:
        engine.dispose()
        if engine.dialect.name == "sqlite":
            raise InputError(f"catalog {describe(url)}: cannot open it ({str(exc.orig).strip()})") from None
        raise CatalogUnreachable(f"catalog {describe(url)}: not reachable ({str(exc.orig).strip().splitlines()[0]})") from None
    return engine
