"""`station catalog`: rebuild, check and synchronise the catalog (docs/catalog.md)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from procedures.engine.errors import InputError

NAME = "catalog"
HELP = "the index of every session, model, table, push, verification and report: rebuild, check, sync"
DESCRIPTION = (
    "The catalog indexes the station's files (<recordings_dir>/catalog.sqlite; a shared PostgreSQL when "
    "[catalog] url is set). rebuild DIR...: recreate the local index from the files; check: list files missing, "
    "changed (sha256) or not indexed; sync: index what is not yet indexed and forward the backlog to the shared "
    "catalog. See docs/catalog.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    for name, text in (("rebuild", "recreate the index from the files under DIR (default: the recordings folder)"),
                       ("check", "list missing, changed and unindexed files (exit 1 when there are any)"),
                       ("sync", "index unindexed files and forward the backlog to the shared catalog"),
                       ("status", "where the catalog is, how many records, backlog, schema revision")):
        q = sub.add_parser(name, help=text, description=text)
        q.add_argument("--config", metavar="C", help="station TOML ([station] recordings_dir, [catalog])")
        if name in ("rebuild", "check", "sync"):
            q.add_argument("dirs", nargs="*", metavar="DIR", help="folders of station files (default: recordings_dir)")
        if name == "rebuild":
            q.add_argument("--db", metavar="FILE.sqlite", help="write the rebuilt index to this file instead")
        if name in ("check", "status"):
            q.add_argument("--json", action="store_true", help="print JSON")


def run(args) -> int:
    from station.catalog import db, files
    from station.catalog.store import Catalog, catalog_of
    from station.services.config import load_config

    cfg = load_config(args.config)
    catalog = catalog_of(cfg)
    if args.action == "rebuild" and args.db:
        catalog = Catalog(local=Path(args.db), station_id=catalog.station_id)
    dirs = getattr(args, "dirs", None) or [cfg.recordings_dir]
    if args.action in ("rebuild", "check", "sync"):
        for d in dirs:
            if not Path(d).is_dir():
                raise InputError(f"{d}: not a folder; give the folder that holds the station's runs")
    if args.action == "rebuild":
        count, problems = files.rebuild(catalog, dirs)
        for p in problems:
            print(f"skipped: {p}")
        print(f"rebuilt {catalog.local} from {', '.join(map(str, dirs))}: {count} records")
        if catalog.url:
            print(f"every record is queued for the shared catalog again ({catalog.backlog()}); `station catalog sync` "
                  "forwards them (records it already holds are skipped)")
        return 0
    if args.action == "check":
        result = files.check(catalog, dirs)
        if args.json:
            print(json.dumps({**result.to_json(), "backlog": catalog.backlog()}, indent=2))
        else:
            for word, items in (("missing", result.missing), ("changed", result.changed),
                                ("not indexed", result.unregistered), ("unreadable", result.unreadable)):
                for item in items:
                    print(f"{word}: {item}")
            backlog = catalog.backlog()
            print(f"{catalog.local}: " + ("every file indexed and unchanged" if result.ok else
                  f"{len(result.missing)} missing, {len(result.changed)} changed, {len(result.unregistered)} not indexed"
                  " (`station catalog sync` indexes them)") + (f"; {backlog} record(s) not yet forwarded" if backlog else ""))
        return 0 if result.ok else 1
    if args.action == "sync":
        count, problems = files.index(catalog, dirs, forward=False)
        for p in problems:
            print(f"skipped: {p}")
        print(f"indexed {count} records from {', '.join(map(str, dirs))} into {catalog.local}")
        if catalog.url:
            result = catalog.forward(force=True)
            if result.error:
                print(f"shared catalog {db.describe(catalog.url)} not reachable ({result.error}): "
                      f"{result.left} record(s) kept in the backlog; run sync again later")
                return 1
            print(f"forwarded {result.forwarded} record(s) to {db.describe(catalog.url)}; backlog empty")
        return 0
    # status
    import sqlalchemy as sa

    with catalog.engine.connect() as conn:
        revision = db.current_revision(conn)
        counts = dict(conn.execute(sa.text("SELECT kind, count(*) FROM records GROUP BY kind")).all())
    status = {"local": str(catalog.local), "shared": db.describe(catalog.url) if catalog.url else None,
              "station_id": catalog.station_id, "revision": revision, "records": counts, "backlog": catalog.backlog()}
    if args.json:
        print(json.dumps(status, indent=2))
    else:
        for k, v in status.items():
            print(f"{k}: {v}")
    return 0
