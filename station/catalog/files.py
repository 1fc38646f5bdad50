"""The files are the records; the catalog indexes them. Finding a folder's records (sessions
.h5, models .json, tables .csv, report folders holding iso230-2.json, audit logs *.jsonl),
rebuilding an index from them, and checking an index against them: files missing or changed
(sha256) since they were indexed, and files not indexed (a write cut short by a kill).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Iterator

import sqlalchemy as sa

from procedures.vocabulary import InputError
from station.catalog import readers
from station.catalog.models import Record
from station.catalog.readers import Rec
from station.catalog.store import Catalog

SKIP_SUFFIXES = (".tmp", ".lock")


@dataclass
class Found:
    """The files of a folder by kind, in the order they are indexed (sessions first, so models and
    reports find their session's serials)."""

    sessions: list[Path] = field(default_factory=list)
    models: list[Path] = field(default_factory=list)
    tables: list[Path] = field(default_factory=list)
    reports: list[Path] = field(default_factory=list)
    logs: list[Path] = field(default_factory=list)


def scan(folders: Iterable[str | os.PathLike]) -> Found:
    found = Found()
    for folder in folders:
        root = Path(folder)
        if not root.is_dir():
            raise InputError(f"{root}: not a folder; give the folder that holds the station's runs")
        for dirpath, dirnames, filenames in os.walk(root):
            dirnames.sort()
            here = Path(dirpath)
            if readers.REPORT_FILE in filenames:
                found.reports.append(here)
            for name in sorted(filenames):
                if name.startswith(".") or name.endswith(SKIP_SUFFIXES):
                    continue
                p = here / name
                if name.endswith(".h5"):
                    found.sessions.append(p)
                elif name.endswith(".jsonl"):
                    found.logs.append(p)
                elif name.endswith(".csv"):
                    found.tables.append(p)
                elif name.endswith(".json") and here not in found.reports:
                    found.models.append(p)
    return found


def indexed_uids(catalog: Catalog) -> set[str]:
    """Every uid the local index holds."""
    with catalog.engine.connect() as conn:
        return set(conn.execute(sa.select(Record.uid)).scalars())


def _known(kind: str, path: Path, known: set[str] | None) -> bool:
    """True when the file's content (its sha256) is indexed already: not read again."""
    if known is None:
        return False
    hashed = path / readers.REPORT_FILE if kind == "report" else path
    try:
        return f"{kind}:{readers.sha256_of(hashed)}" in known
    except OSError:
        return False


def recs_of(found: Found, catalog: Catalog | None, problems: list[str], known: set[str] | None = None) -> Iterator[Rec]:
    """Records of the files in `found`; a file that cannot be read is named in `problems`.
    Files whose content `known` holds (uids) are skipped: a session's figures take seconds."""
    for path in found.sessions:
        if _known("session", path, known):
            continue
        try:
            yield readers.session_rec(path)
        except InputError as exc:
            problems.append(str(exc).splitlines()[0])
    lookup = catalog.serials_of_source if catalog is not None else None
    for path in found.models:
        # a .json that is no model may be a certificate's (station.catalog.certificates)
        rec = None if _known("model", path, known) else (readers.model_rec(path, lookup) or _certificate_rec(path))
        if rec is not None:
            yield rec
    for path in found.tables:
        rec = None if _known("table", path, known) else readers.table_rec(path)
        if rec is not None:
            yield rec
    for folder in found.reports:
        rec = None if _known("report", folder, known) else readers.report_rec(folder, lookup)
        if rec is not None:
            yield rec
    for path in found.logs:
        yield from (r for r in readers.audit_recs(path) if known is None or r.uid not in known)


def _certificate_rec(path: Path) -> Rec | None:
    from station.catalog.certificates import certificate_rec_of_json  # noqa: PLC0415

    return certificate_rec_of_json(path)


def index(catalog: Catalog, folders: Iterable[str | os.PathLike], forward: bool = True) -> tuple[int, list[str]]:
    """Index every record file under `folders` that is not indexed yet (indexed content is
    skipped by its key, unread; a file rewritten in place retires its earlier record).
    (records indexed now, problems)."""
    problems: list[str] = []
    found = scan(folders)
    known = indexed_uids(catalog) if catalog.local.exists() else set()
    count = 0
    # sessions first, committed, so models and reports can look up their serials
    for group in (Found(sessions=found.sessions), Found(models=found.models, tables=found.tables, reports=found.reports,
                                                        logs=found.logs)):
        recs = list(recs_of(group, catalog, problems, known))
        count += len(recs)
        catalog.ingest(recs, forward=False)
    if forward:
        catalog.forward()
    return count, problems


def rebuild(catalog: Catalog, folders: Iterable[str | os.PathLike]) -> tuple[int, list[str]]:
    """Recreate `catalog`'s local index from the files under `folders` (the old index file is
    replaced; the files are the records)."""
    catalog.close()
    for suffix in ("", "-wal", "-shm"):
        Path(str(catalog.local) + suffix).unlink(missing_ok=True)
    return index(catalog, folders, forward=False)


@dataclass
class CheckResult:
    missing: list[str] = field(default_factory=list)
    changed: list[str] = field(default_factory=list)
    unregistered: list[str] = field(default_factory=list)
    unreadable: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not (self.missing or self.changed or self.unregistered)

    def to_json(self) -> dict:
        return {"missing": self.missing, "changed": self.changed, "unregistered": self.unregistered,
                "unreadable": self.unreadable}


def check(catalog: Catalog, folders: Iterable[str | os.PathLike]) -> CheckResult:
    """Compare the local index with the files under `folders`."""
    result = CheckResult()
    with catalog.engine.connect() as conn:
        rows = conn.execute(sa.select(Record.uid, Record.kind, Record.path, Record.sha256)).all()
    indexed = {uid for uid, *_ in rows}
    for uid, kind, path, sha in rows:
        if kind in readers.AUDIT_KINDS.values():
            continue  # audit entries: their log is checked line by line below
        target = Path(path) / readers.REPORT_FILE if kind == "report" else Path(path or "")
        if not target.is_file():
            result.missing.append(f"{kind} {path}")
        elif readers.sha256_of(target) != sha:
            result.changed.append(f"{kind} {path} (sha256 {sha[:12]}... indexed, {readers.sha256_of(target)[:12]}... now)")
    found = scan(folders)
    for kind, paths, read in (("session", found.sessions, readers.session_rec), ("model", found.models, readers.model_rec),
                              ("table", found.tables, readers.table_rec), ("report", found.reports, readers.report_rec)):
        for path in paths:
            hashed = path / readers.REPORT_FILE if kind == "report" else path
            if f"{kind}:{readers.sha256_of(hashed)}" not in indexed:
                _unregistered(result, path, kind, lambda: read(path))
    for path in found.logs:
        for rec in readers.audit_recs(path):
            if rec.uid not in indexed:
                result.unregistered.append(f"{rec.kind} {path} entry {rec.key}")
    return result


def _unregistered(result: CheckResult, path: Path, kind: str, read) -> None:
    """A file whose key is not indexed: unregistered if it is a record at all."""
    try:
        rec = read()
    except InputError as exc:
        result.unreadable.append(str(exc).splitlines()[0])
        return
    if rec is not None:
        result.unregistered.append(f"{kind} {path}")


def records_json(engine: sa.Engine) -> list[dict]:
    """Every record with its legs, ordered by uid (comparisons, `catalog export`)."""
    from station.catalog.models import RecordLeg

    with engine.connect() as conn:
        recs = [dict(r._mapping) for r in conn.execute(sa.select(Record.__table__).order_by(Record.uid))]
        legs: dict[str, list] = {}
        for r in conn.execute(sa.select(RecordLeg.__table__).order_by(RecordLeg.uid, RecordLeg.leg)):
            legs.setdefault(r.uid, []).append(dict(r._mapping))
    for r in recs:
        r["legs"] = legs.get(r["uid"], [])
    return json.loads(json.dumps(recs, default=str))
