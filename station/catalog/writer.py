"""Where the station's work meets the catalog: the runner sink that indexes a run's session file
and audit entries when the run closes, and `register` for the jobs that write models, tables
and reports. Neither ever fails the work: the files are written first and are the records; a
catalog that cannot be written is logged, and `station catalog sync` indexes what was missed.

STATION_CATALOG=off in the environment turns catalog writes off (the test suite does, so a
test's run never lands in a catalog under the working folder unless it asks for one).

The catalog (SQLAlchemy, Alembic: about half a second of imports) is imported only where it is
used, so a sweep's first point does not wait for it (`CatalogSink.deferred`; bench/bench_startup.py).
"""

from __future__ import annotations

import logging
import os
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from procedures.engine import events as ev

if TYPE_CHECKING:
    from procedures.compensation.audit import AuditSink
    from station.catalog.store import Catalog
    from station.services.config import StationConfig

log = logging.getLogger(__name__)


def enabled() -> bool:
    return os.environ.get("STATION_CATALOG", "").strip().lower() not in ("off", "0", "no", "false")


def catalog_for(cfg: StationConfig) -> Catalog | None:
    """The catalog of a station config, or None when catalog writes are off. With a shared
    catalog, a backlog left by earlier work starts going out now, in a thread (a job starting is
    the "next write" the backlog waits for; the job does not wait for it)."""
    if not enabled():
        return None
    from station.catalog.store import catalog_of

    catalog = catalog_of(cfg)
    if catalog.url:
        threading.Thread(target=_forward_quietly, args=(catalog,), name="catalog-forward", daemon=False).start()
    return catalog


def _forward_quietly(catalog: Catalog) -> None:
    try:
        if catalog.local.exists() and catalog.backlog():
            catalog.forward()
    except Exception as exc:  # never the job's concern: the backlog stays for the next write or sync
        log.info("catalog %s: backlog not forwarded (%s)", catalog.local, exc)


class CatalogSink:
    """A runner sink (not critical) that indexes, when the run closes, the session file the run
    recorded (`session_path`, already finished by the recorder, which closes before it) and the
    audit entries `audit_sink` wrote (procedures.compensation.audit.AuditSink).

    `CatalogSink.deferred(cfg, ...)` opens the station's catalog itself, in a thread started at
    the run's second point (or when it closes, if there was none): the catalog's imports
    are not on the way to the first point, and a shared catalog's backlog still starts going out
    during the run (catalog_for). The indexing thread ("catalog-index", not a daemon: the process
    finishes it before it exits) waits for the catalog to be open."""

    critical = False

    def __init__(self, catalog: Catalog | None, session_path: str | os.PathLike | None = None,
                 audit_sink: AuditSink | None = None, *, opener: Callable[[], Catalog | None] | None = None) -> None:
        self.catalog = catalog
        self.session_path = Path(session_path) if session_path else None
        self.audit_sink = audit_sink
        self.uids: list[str] = []
        self.thread: threading.Thread | None = None
        self._opener = opener
        self._opening: threading.Thread | None = None
        self._points_seen = False

    @classmethod
    def deferred(cls, cfg: StationConfig, session_path: str | os.PathLike | None = None,
                 audit_sink: AuditSink | None = None) -> CatalogSink:
        """The sink for the catalog of `cfg` (catalog_for), opened off the run's way (see the class);
        one that does nothing when catalog writes are off."""
        if not enabled():
            return cls(None, session_path, audit_sink)
        return cls(None, session_path, audit_sink, opener=lambda: catalog_for(cfg))

    def handle(self, event: ev.Event) -> None:
        # opened at the second point: every sink has shown the first one by then (this sink
        # comes before the display's), and no import competes with it for the interpreter
        if self._opener is not None and self._opening is None and isinstance(event, ev.PointMeasured):
            if self._points_seen:
                self._open_in_thread()
            self._points_seen = True

    def _open_in_thread(self) -> None:
        self._opening = threading.Thread(target=self._open, name="catalog-open", daemon=False)
        self._opening.start()

    def _open(self) -> None:
        try:
            self.catalog = self._opener()
        except Exception as exc:  # never the run's concern: the files are the records
            log.warning("catalog: not opened (%s); `station catalog sync` indexes it later", exc)

    def close(self, outcome: str) -> None:
        if self._opener is not None:
            if self._opening is None:
                self._open_in_thread()
            self.thread = threading.Thread(target=self._index_when_open, name="catalog-index", daemon=False)
            self.thread.start()
            return
        if self.catalog is None:
            return
        self._index_audit()
        if self._has_session():
            # the session's ISO 230-2 budget takes seconds on a long sweep: not on the run's way
            # out (a non-daemon thread: the process still finishes it before it exits)
            self.thread = threading.Thread(target=self._index_session, name="catalog-index", daemon=False)
            self.thread.start()

    def _has_session(self) -> bool:
        return self.session_path is not None and self.session_path.is_file()

    def _index_when_open(self) -> None:
        self._opening.join()
        if self.catalog is None:
            return
        self._index_audit()
        if self._has_session():
            self._index_session()

    def _index_audit(self) -> None:
        if self.audit_sink is None:
            return
        try:
            from station.catalog import readers

            recs = [readers.audit_rec(e.to_json(), self.audit_sink.log.path) for e in self.audit_sink.written]
            self.uids += self.catalog.ingest([r for r in recs if r is not None])
        except Exception as exc:  # the log is written; `station catalog sync` indexes it later
            log.warning("catalog %s: not written (%s); `station catalog sync` indexes it later", self.catalog.local, exc)

    def _index_session(self) -> None:
        try:
            from station.catalog import readers

            self.uids += self.catalog.ingest([readers.session_rec(self.session_path)])
        except Exception as exc:
            log.warning("catalog %s: %s not indexed (%s); `station catalog sync` indexes it later",
                        self.catalog.local, self.session_path, exc)


def register(catalog: Catalog | None, path: str | os.PathLike, kind: str) -> list[str]:
    """Index a model file, table CSV or report folder just written ("model", "table", "report");
    the uids written ([] when off or on failure, which is logged)."""
    if catalog is None:
        return []
    from station.catalog import readers

    try:
        if kind == "model":
            rec = readers.model_rec(path, catalog.serials_of_source)
        elif kind == "table":
            rec = readers.table_rec(path)
        elif kind == "report":
            rec = readers.report_rec(path, catalog.serials_of_source)
        else:
            raise ValueError(f"unknown kind {kind!r}")
        return catalog.ingest([rec]) if rec is not None else []
    except Exception as exc:
        log.warning("catalog %s: %s not indexed (%s); `station catalog sync` indexes it later", catalog.local, path, exc)
        return []
