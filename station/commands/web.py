"""`station web`: the fleet web view (read-only) on 127.0.0.1:8800."""

from __future__ import annotations

from pathlib import Path


NAME = "web"
HELP = "the fleet web view: legs, a leg's history, control charts, station comparison (read-only)"
DESCRIPTION = (
    "Serve read-only HTML pages over the catalog: the fleet (filters by type, station, dates, due, ISO 14253-1 "
    "decision), a leg's "
    "history of E, B, R with U and tolerance lines, tables pushed and certificates, control charts per leg type "
    "with Cpk, the station comparison (E_n). Bound to 127.0.0.1 unless --host says otherwise. docs/web.md."
)


def add_arguments(p) -> None:
    p.add_argument("--catalog", metavar="URL", help="catalog URL or SQLite file (default: the config's shared "
                   "catalog when set, else its local one)")
    p.add_argument("--config", metavar="C", help="station TOML ([catalog], [tolerances.TYPE], recordings_dir)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=int, default=8800, help="port (default 8800)")


def run(args) -> int:
    from station.catalog import db
    from station.catalog.store import LOCAL_NAME
    from station.services.config import load_config
    import uvicorn
    from station.web.app import WebSettings, create_app
    from station.web.engine import catalog_url, open_readonly
    from station.web.extensions import decision_tolerances_of, tolerances_of

    cfg = load_config(args.config)
    runs = Path(cfg.recordings_dir)
    url = catalog_url(args.catalog) if args.catalog else (cfg.catalog.url or db.sqlite_url(runs / LOCAL_NAME))
    engine = open_readonly(url, cfg.catalog.connect_timeout_s)
    settings = WebSettings(tolerances=tolerances_of(args.config), runs_dir=runs,
                           decision_tolerances=decision_tolerances_of(args.config),
                           interval_days=cfg.catalog.calibration_interval_days,
                           where=f"catalog: {db.describe(url)} (read-only)")
    print(f"station web: http://{args.host}:{args.port}/ ({settings.where}); Ctrl-C stops it", flush=True)
    uvicorn.run(create_app(engine, settings), host=args.host, port=args.port, log_level="warning")
    return 0
