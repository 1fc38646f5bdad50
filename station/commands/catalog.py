"""`station catalog`: rebuild, check and synchronise the catalog (docs/catalog.md)."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import json
from pathlib import Path

from procedures.vocabulary import InputError

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
                       ("check", "list missing, changed and unindexed files and the records waiting for the "
                                 "shared catalog (exit 0 all agree, 1 files and index disagree, 3 only records "
                                 "wait in the outbox)"),
                       ("sync", "index unindexed files and forward the backlog to the shared catalog"),
                       ("status", "where the catalog is, how many records, backlog, schema revision")):
        q = sub.add_parser(name, help=text, description=text)
        q.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML ([station] recordings_dir, [catalog])")
        if name in ("rebuild", "check", "sync"):
            q.add_argument("dirs", type=V.IN_DIR.argtype(), nargs="*", metavar="DIR", help="folders of station files (default: recordings_dir)")
        if name == "rebuild":
            q.add_argument("--db", type=V.OUT_FILE.argtype(), metavar="FILE.sqlite", help="write the rebuilt index to this file instead")
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
        backlog = catalog.backlog()
        # exit codes (docs/catalog.md): 0 every file indexed and unchanged and nothing waiting for
        # the shared catalog; 1 files and index disagree (`sync` mends what is not indexed);
        # 3 they agree but records wait in the outbox (the `backlog` `status` reports: `sync`)
        rc = 1 if not result.ok else (3 if backlog else 0)
        if args.json:
            print(json.dumps({**result.to_json(), "backlog": backlog, "exit": rc}, indent=2))
        else:
            for word, items in (("missing", result.missing), ("changed", result.changed),
                                ("not indexed", result.unregistered), ("unreadable", result.unreadable)):
                for item in items:
                    print(f"{word}: {item}")
            print(f"{catalog.local}: " + ("every file indexed and unchanged" if result.ok else
                  f"{len(result.missing)} missing, {len(result.changed)} changed, {len(result.unregistered)} not indexed"
                  " (`station catalog sync` indexes them)") +
                  (f"; {backlog} record(s) wait in the outbox for the shared catalog (`station catalog sync`)"
                   if backlog else ""))
        return rc
    if args.action == "sync":
        count, problems = files.index(catalog, dirs, forward=False)
        for p in problems:
            print(f"skipped: {p}")
        print(f"indexed {count} new record(s) from {', '.join(map(str, dirs))} into {catalog.local} "
              "(records indexed before are not read or queued again)")
        if catalog.url:
            result = catalog.forward(force=True)
            if result.error:
                print(f"shared catalog {db.describe(catalog.url)} not reachable ({result.error}): "
                      f"{result.left} record(s) kept in the backlog; run sync again later")
                return 1
            print(f"forwarded {result.forwarded} record(s) to {db.describe(catalog.url)}; outbox empty")
        return 0
    # status
    import sqlalchemy as sa

    with catalog.engine.connect() as conn:
        revision = db.current_revision(conn)
        counts = dict(conn.execute(sa.text("SELECT kind, count(*) FROM records GROUP BY kind")).all())
        # the stage of the leg's life (procedures/io/recording/stage.py); models, tables, reports have none
        stages = {k or "none": n for k, n in conn.execute(
            sa.text("SELECT stage, count(*) FROM records GROUP BY stage ORDER BY stage")).all()}
    status = {"local": str(catalog.local), "shared": db.describe(catalog.url) if catalog.url else None,
              "station_id": catalog.station_id, "revision": revision, "records": counts, "stages": stages,
              "backlog": catalog.backlog()}
    if args.json:
        print(json.dumps(status, indent=2))
    else:
        for k, v in status.items():
            print(f"{k}: {v}")
    return 0
