"""The web view at scale: a catalog of 10 000 legs x 5 calibrations (bench_catalog's synthetic
records through the catalog API) on SQLite and, when initdb is installed, a throwaway PostgreSQL
(tests/pg.py). Times the fleet page (goal < 1 s) and a leg's page (goal < 300 ms) server side
(FastAPI TestClient, median of repeats), the decision filter (goal < 300 ms: verdicts stored at
ingest), the control charts of a leg type and the station comparison, and in headless Chromium (selenium; the navigation's
duration, request to load event, from the Navigation Timing API) side by side. Beside the server's wall
time, its CPU time per request (this process, which runs the app, plus the PostgreSQL server's
processes): on a machine shared with other work the wall time grows with the load average, the CPU
time hardly does.

    .venv/bin/python bench/bench_web.py [--legs 10000] [--calibrations 5] [--no-browser]
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from bench_catalog import BATCH, TYPES, synthetic, timed  # noqa: E402

from station.catalog import db  # noqa: E402
from station.catalog.store import Catalog, write_recs  # noqa: E402
from station.web.app import WebSettings, create_app  # noqa: E402
from station.web.engine import open_readonly  # noqa: E402

GOALS_MS = {"fleet": 1000, "fleet --type": 1000, "fleet --due": 1000, "fleet --decision": 300, "leg": 300,
            "charts": 300, "compare": 1000}


def fill(ingest, n_legs: int, n_cal: int) -> None:
    """The synthetic records, each session decided as a session file is at ingest
    (station.catalog.readers.decide_legs, revision 0004) against the bench's tolerances."""
    from station.catalog.readers import decide_legs

    tol = tolerances()
    batch = []
    for rec in synthetic(n_legs, n_cal):
        batch.append(decide_legs(rec, tol))
        if len(batch) == BATCH:
            ingest(batch)
            batch = []
    if batch:
        ingest(batch)


def pages(n_legs: int) -> dict[str, str]:
    serial = f"HX-{random.Random(3).randrange(n_legs):05d}"
    return {"fleet": "/", "fleet --type": "/?type=HX-L450&page=3", "fleet --due": "/?due=2025-06-01",
            "fleet --decision": "/?decision=not-conforming", "leg": f"/leg/{serial}",
            "charts": f"/charts?type={TYPES[1]}", "compare": "/compare"}


def tolerances():
    """Limits for every leg type, so each leg of the fleet is decided (ISO 14253-1) on every page."""
    from procedures.reporting.decision import Tolerance

    return {t: Tolerance(t, {"E": 10.0, "B": 3.0, "R": 4.0}, {"E": 6.0, "B": 2.0, "R": 3.0}) for t in TYPES}


def server_cpu_s(url: str):
    """A function giving the CPU seconds (user + system) spent so far by the PostgreSQL cluster
    serving `url` (its postmaster's children: the backends), 0 for SQLite (in process)."""
    from urllib.parse import parse_qs, urlsplit

    host = (parse_qs(urlsplit(url).query).get("host") or [""])[0] if url.startswith("postgresql") else ""
    pid_file = Path(host) / "data" / "postmaster.pid"
    if not host or not pid_file.exists():
        return lambda: 0.0
    postmaster = pid_file.read_text().split()[0]
    tick = os.sysconf("SC_CLK_TCK")

    def cpu() -> float:
        total = 0
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                fields = stat.read_text().rsplit(")", 1)[1].split()
            except OSError:  # a process that ended meanwhile
                continue
            if fields[1] == postmaster:  # ppid
                total += int(fields[11]) + int(fields[12])  # utime, stime
        return total / tick

    return cpu


def measure(url: str, n_legs: int, driver) -> dict[str, list]:
    """{page: [server wall ms, server CPU ms, browser ms]}."""
    import time

    from fastapi.testclient import TestClient

    from tests.web.browser import Server

    engine = open_readonly(url)
    app = create_app(engine, WebSettings(decision_tolerances=tolerances()))
    out = {}
    db_cpu = server_cpu_s(url)
    with TestClient(app) as client:
        for name, path in pages(n_legs).items():
            r = client.get(path)
            assert r.status_code == 200, (path, r.status_code)
            cpu0, db0 = time.process_time(), db_cpu()
            wall = timed(lambda: client.get(path), 7)
            cpu_ms = ((time.process_time() - cpu0) + (db_cpu() - db0)) / 7 * 1000
            out[name] = [wall, cpu_ms, None]
    if driver is not None:
        server = Server(app)
        try:
            for name, path in pages(n_legs).items():
                durations = []
                for _ in range(5):
                    driver.get(server.url + path)
                    durations.append(driver.execute_script(
                        "return performance.getEntriesByType('navigation')[0].duration"))
                out[name][2] = sorted(durations)[len(durations) // 2]
        finally:
            server.stop()
    engine.dispose()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--legs", type=int, default=10_000, help="legs in the synthetic catalog (default 10000)")
    ap.add_argument("--calibrations", type=int, default=5, help="calibrations per leg (default 5)")
    ap.add_argument("--no-browser", action="store_true", help="server side only (no Chromium)")
    args = ap.parse_args()
    driver = None
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as d:
        from tests.web.browser import CHROMIUM, DRIVER, chromium

        if args.no_browser:
            print("browser: not measured (--no-browser)", flush=True)
        elif CHROMIUM and DRIVER:
            driver = chromium(Path(d) / "profile", Path(d) / "downloads")
        else:
            print("browser: not measured (apt-get install chromium chromium-driver)")
        try:
            cat = Catalog(local=Path(d) / "catalog.sqlite", station_id="bench")
            fill(lambda recs: cat.ingest(recs), args.legs, args.calibrations)
            cat.close()
            results["SQLite"] = measure(db.sqlite_url(Path(d) / "catalog.sqlite"), args.legs, driver)
            from tests.pg import bench_engine

            with bench_engine(lambda conn, recs: write_recs(conn, recs, "bench", queue=False), args.legs,
                              args.calibrations, fill) as url:
                if url is not None:
                    results["PostgreSQL"] = measure(url, args.legs, driver)
        finally:
            if driver is not None:
                driver.quit()
    print(f"\nweb view over a catalog of {args.legs} legs x {args.calibrations} calibrations "
          f"(50 legs a page; median ms)")
    print(f"{'engine':<11} {'page':<16} {'server ms':>10} {'server CPU ms':>14} {'browser ms':>11} {'goal ms':>8}")
    for engine_name, rows in results.items():
        for name, (server_ms, cpu_ms, browser_ms) in rows.items():
            b = f"{browser_ms:.0f}" if browser_ms is not None else "-"
            print(f"{engine_name:<11} {name:<16} {server_ms:>10.0f} {cpu_ms:>14.0f} {b:>11} {GOALS_MS[name]:>8}")
    print("server: TestClient request to response in process (median wall); server CPU: mean CPU time per request of "
          "this process and the database server's; browser: Chromium navigation, request to load event")
    print(f"load average while measuring: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (wall times grow with it)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
