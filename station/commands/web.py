"""`station web`: the fleet web view (read-only) on 127.0.0.1:8800."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

from pathlib import Path


NAME = "web"
HELP = "the fleet web view: legs, a leg's history, control charts, station comparison (read-only)"
DESCRIPTION = (
    "Serve read-only HTML pages over the catalog: the fleet (filters by type, station, dates, due, ISO 14253-1 "
    "decision), a leg's "
    "history of E, B, R with U and tolerance lines, tables pushed and certificates, control charts per leg type "
    "with Cpk, the station comparison (E_n). Bound to 127.0.0.1 unless --host says otherwise; beyond this "
    "machine only with a login ([web.users.NAME] in --config) and TLS in front. docs/web.md."
)


def add_arguments(p) -> None:
    p.add_argument("--catalog", type=V.CATALOG.argtype(), metavar="URL", help="catalog URL or SQLite file (default: the config's shared "
                   "catalog when set, else its local one)")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML ([catalog], [tolerances.TYPE], recordings_dir)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=V.PORT.argtype(), default=8800, help="port (default 8800)")
    p.add_argument("--hash-password", action="store_true", help="read a password (typed twice, not echoed; or "
                   "the first line of a pipe) and print its argon2id hash for [web.users.NAME] password_hash; "
                   "serves nothing")


def run(args) -> int:
    if args.hash_password:
        return _hash_password()
    from station.catalog import db
    from station.catalog.store import LOCAL_NAME
    from station.services.config import load_config
    import uvicorn

    from station.web.access import Guard, parse_web_section
    from station.web.app import WebSettings, create_app
    from station.web.engine import catalog_url, open_readonly, what_to_check
    from station.web.extensions import decision_tolerances_of, tolerances_of
    from station.web.listen import bind, check_port, login_needed

    cfg = load_config(args.config)
    # where it listens and who may read, checked before the catalog is opened or a URL printed
    port = check_port(args.port)
    access = parse_web_section(args.config, cfg.web)
    login = login_needed(args.host, access, args.config)
    sock = bind(args.host, port)
    try:
        runs = Path(cfg.recordings_dir)
        url = catalog_url(args.catalog) if args.catalog else (cfg.catalog.url or db.sqlite_url(runs / LOCAL_NAME))
        engine = open_readonly(url, cfg.catalog.connect_timeout_s)
        settings = WebSettings(tolerances=tolerances_of(args.config), runs_dir=runs,
                               decision_tolerances=decision_tolerances_of(args.config),
                               interval_days=cfg.catalog.calibration_interval_days,
                               compare_window_days=cfg.catalog.compare_window_days,
                               where=f"catalog: {db.describe(url)} (read-only)", check_hint=what_to_check(url))
        app = Guard(create_app(engine, settings), host=args.host, port=port, access=access, login=login)
        shown = f"[{args.host}]" if ":" in args.host else args.host
        print(f"station web: http://{shown}:{port}/ ({settings.where}"
              f"{'; login required' if login else ''}); Ctrl-C stops it", flush=True)
        uvicorn.Server(uvicorn.Config(app, log_level="warning")).run(sockets=[sock])
    finally:
        sock.close()
    return 0


def _hash_password() -> int:
    import getpass
    import sys

    from procedures.vocabulary import InputError
    from station.web.access import hash_password

    if sys.stdin.isatty():  # typed: not echoed, asked twice against typos
        first = getpass.getpass("password: ")
        if len(first) >= 12 and getpass.getpass("again: ") != first:
            raise InputError("password: the two entries differ; nothing printed")
    else:  # piped (a script, a secret store): its first line
        first = sys.stdin.readline().rstrip("\r\n")
    if len(first) < 12:
        raise InputError("password: give at least 12 characters")
    print(hash_password(first))
    return 0
