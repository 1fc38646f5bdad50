"""Opening a catalog for the web view: migrated once by the catalog's own `open_engine` (so an
older catalog is brought to this station's schema, a newer one refused in one line), then
reopened read-only where the engine allows: SQLite with `mode=ro`, PostgreSQL with
`default_transaction_read_only`, so no page can write.
"""

from __future__ import annotations

from pathlib import Path

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from procedures.vocabulary import InputError
from station.catalog import db


def catalog_url(text: str) -> str:
    """A URL for `--catalog`: a database URL as given, a plain path as an SQLite file."""
    return text if "://" in text else db.sqlite_url(Path(text).expanduser().resolve())


SQLITE_MAGIC = b"SQLite format 3\x00"


def what_to_check(url: str) -> str:
    """What an operator checks when the catalog at `url` does not answer (for the refusal at start
    and the 503 page): the server and the URL, never the driver's text."""
    try:
        u = sa.engine.make_url(url)
    except Exception:
        return "check --catalog / [catalog] url"
    if u.get_backend_name() == "sqlite":
        return (f"check that the file {u.database} exists and is readable (`station catalog sync` creates it) "
                "and the disk is mounted")
    where = f"{u.host or 'localhost'}:{u.port or 5432}" if u.host else f"the socket in {u.query.get('host', 'the default folder')}"
    return (f"check that the PostgreSQL server at {where} is running and reachable from this machine "
            f"(e.g. `pg_isready -h {u.host or u.query.get('host', 'localhost')} -p {u.port or 5432}`), that database "
            f"{u.database or '?'} exists and user {u.username or '?'} may connect, and the URL (--catalog or "
            "[catalog] url)")


def _check_sqlite_file(path: Path) -> None:
    """InputError unless `path` is an SQLite file: a TOML or any other file given as --catalog is
    named for what it is (opening it would have SQLite migrate, i.e. write, whatever it is)."""
    if not path.is_file():
        raise InputError(f"catalog {path}: no such file; `station catalog sync` creates and fills it")
    try:
        with open(path, "rb") as fh:
            head = fh.read(len(SQLITE_MAGIC))
    except OSError as exc:
        raise InputError(f"catalog {path}: cannot read it ({exc.strerror or exc})") from None
    if head != SQLITE_MAGIC:
        hint = "; a station config goes with --config" if path.suffix.lower() == ".toml" else ""
        raise InputError(f"catalog {path}: not an SQLite catalog (give runs/catalog.sqlite, or a "
                         f"postgresql:// URL){hint}")


def open_readonly(url: str, connect_timeout_s: float = 2.0) -> Engine:
    """A read-only engine on the catalog at `url`. InputError when a local file does not exist or
    is no SQLite file, or the server does not answer (one line naming what to check)."""
    u = db.make_engine(url, connect_timeout_s).url
    if u.get_backend_name() == "sqlite":
        if not u.database:
            raise InputError(f"catalog {url}: names no file; give the catalog.sqlite file")
        _check_sqlite_file(Path(u.database))
        try:
            db.open_engine(url).dispose()
        except sa.exc.DatabaseError as exc:  # a damaged file: SQLite's own word, one line
            raise InputError(f"catalog {u.database}: cannot open it ({str(exc.orig).strip()})") from None
        return sa.create_engine(f"sqlite:///file:{Path(u.database).resolve()}?mode=ro&uri=true")
    try:
        db.open_engine(url, connect_timeout_s).dispose()
    except (db.CatalogUnreachable, sa.exc.OperationalError, sa.exc.InterfaceError):
        raise InputError(f"catalog {db.describe(url)}: not reachable within {connect_timeout_s:g} s; "
                         f"{what_to_check(url)}") from None
    return sa.create_engine(u.set(drivername="postgresql+psycopg"), pool_pre_ping=True, connect_args={
        "connect_timeout": max(1, int(round(connect_timeout_s))), "options": "-c default_transaction_read_only=on"})
