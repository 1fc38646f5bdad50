"""Opening a catalog for the web view: migrated once by the catalog's own `open_engine` (so an
older catalog is brought to this station's schema, a newer one refused in one line), then
reopened read-only where the engine allows: SQLite with `mode=ro`, PostgreSQL with
`default_transaction_read_only`, so no page can write.
"""

from __future__ import annotations

from pathlib import Path

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from procedures.engine.errors import InputError
from station.catalog import db


def catalog_url(text: str) -> str:
    """A URL for `--catalog`: a database URL as given, a plain path as an SQLite file."""
    return text if "://" in text else db.sqlite_url(Path(text).expanduser().resolve())


def open_readonly(url: str, connect_timeout_s: float = 2.0) -> Engine:
    """A read-only engine on the catalog at `url`. InputError when a local file does not exist."""
    u = db.make_engine(url, connect_timeout_s).url
    if u.get_backend_name() == "sqlite":
        if not u.database or not Path(u.database).is_file():
            raise InputError(f"catalog {u.database}: no such file; `station catalog sync` creates and fills it")
        db.open_engine(url).dispose()
        return sa.create_engine(f"sqlite:///file:{Path(u.database).resolve()}?mode=ro&uri=true")
    db.open_engine(url, connect_timeout_s).dispose()
    return sa.create_engine(u.set(drivername="postgresql+psycopg"), pool_pre_ping=True, connect_args={
        "connect_timeout": max(1, int(round(connect_timeout_s))), "options": "-c default_transaction_read_only=on"})
