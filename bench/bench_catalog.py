"""Catalog at scale: 10 000 legs x 5 calibrations (50 000 session records, one leg each, with
ISO 230-2 figures), inserted through the catalog API into SQLite and into a throwaway PostgreSQL
(tests/pg.py; skipped with a note when PostgreSQL is not installed). Prints per engine: records
ingested per second, `history` of one leg (goal < 50 ms) and `legs` with filters (goal < 300 ms).

    .venv/bin/python bench/bench_catalog.py [--legs 10000] [--calibrations 5]
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import sys
import tempfile
import time
from datetime import datetime, timedelta, timezone
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from station.catalog import db  # noqa: E402
from station.catalog.history import history, legs  # noqa: E402
from station.catalog.readers import Rec  # noqa: E402
from station.catalog.store import Catalog, write_recs  # noqa: E402

TYPES = ("HX-L300", "HX-L450", "HX-L600")
STATIONS = ("ST-A", "ST-B", "ST-C")
BATCH = 1000


def synthetic(n_legs: int, n_cal: int, seed: int = 1):
    """Records in time order: calibration k of every leg, k = 0..n_cal-1, about 73 days apart."""
    rnd = random.Random(seed)
    t0 = datetime(2024, 1, 1, tzinfo=timezone.utc)
    for k in range(n_cal):
        for i in range(n_legs):
            serial = f"HX-{i:05d}"
            t = t0 + timedelta(days=73 * k + i % 60, seconds=i)
            rec = Rec(kind="session", key=f"{k:02d}{i:062d}", time_utc=t.strftime("%Y-%m-%dT%H:%M:%S.%fZ"),
                      station_id=STATIONS[(i + k) % 3], operator="bench", software_version="bench",
                      outcome="completed", path=f"/runs/{serial}/{k}.h5", sha256=f"{k:02d}{i:062d}")
            figs = {}
            for name in ("E", "A", "B", "R", "M"):
                figs[f"{name}_um"] = rnd.uniform(0.5, 10.0)
                figs[f"{name}_U_um"] = rnd.uniform(0.05, 0.5)
            rec.legs[1 + i % 6] = {"leg_serial": serial, **figs}
            rec.leg_info[serial] = {"part_number": "P-1", "leg_type": TYPES[i % 3], "screw_lot": f"L{i % 40}"}
            yield rec


def timed(fn, repeat: int) -> float:
    """Median wall time of `fn()` in ms."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t) * 1000)
    return statistics.median(times)


def ingest_all(ingest, n_legs: int, n_cal: int) -> tuple[int, float]:
    """Every synthetic record through `ingest` in batches: (records, records per second)."""
    t = time.perf_counter()
    batch: list[Rec] = []
    n = 0
    for rec in synthetic(n_legs, n_cal):
        batch.append(rec)
        if len(batch) == BATCH:
            ingest(batch)
            n += len(batch)
            batch = []
    if batch:
        ingest(batch)
        n += len(batch)
    return n, n / (time.perf_counter() - t)


def measure(name: str, engine, n_legs: int, n_cal: int, ingested: tuple[int, float]) -> dict:
    """The query figures on a filled catalog; `ingested` = ingest_all's (records, rate)."""
    n, rate = ingested
    rnd = random.Random(7)
    serials = [f"HX-{rnd.randrange(n_legs):05d}" for _ in range(20)]
    it = iter(serials * 10)
    h_ms = timed(lambda: history(engine, next(it)), 20)
    h = history(engine, serials[0])
    assert len(h.calibrations) == n_cal and len(h.drift) == n_cal - 1
    filters = {
        "all": {},
        "--type": {"leg_type": "HX-L450"},
        "--station --since": {"station": "ST-B", "since": "2024-06-01"},
        "--due 2025-12-01": {"due_by": "2025-12-01"},
    }
    legs_ms = {}
    for label, kw in filters.items():
        rows = legs(engine, **kw)
        legs_ms[label] = (timed(lambda: legs(engine, **kw), 5), len(rows))
    return {"engine": name, "records": n, "rate": rate, "history_ms": h_ms, "legs": legs_ms}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--legs", type=int, default=10_000)
    ap.add_argument("--calibrations", type=int, default=5)
    args = ap.parse_args()
    results = []
    with tempfile.TemporaryDirectory() as d:
        cat = Catalog(local=Path(d) / "catalog.sqlite", station_id="bench")
        ingested = ingest_all(cat.ingest, args.legs, args.calibrations)
        results.append(measure("SQLite", cat.engine, args.legs, args.calibrations, ingested))
        cat.close()
    pg: dict[str, tuple[int, float]] = {}

    def fill(ingest, n_legs, n_cal):
        pg["ingested"] = ingest_all(ingest, n_legs, n_cal)

    from tests.pg import bench_engine

    with bench_engine(lambda conn, recs: write_recs(conn, recs, "bench", queue=False), args.legs, args.calibrations,
                      fill) as url:
        if url is not None:
            engine = db.open_engine(url)
            results.append(measure("PostgreSQL", engine, args.legs, args.calibrations, pg["ingested"]))
            engine.dispose()
    n = args.legs * args.calibrations
    print(f"\ncatalog at {args.legs} legs x {args.calibrations} calibrations = {n} session records "
          f"(batches of {BATCH} through the catalog API)")
    labels = list(results[0]["legs"])
    head = f"{'engine':<11} {'records/s':>10} {'history ms':>11}" + "".join(f" {'legs ' + l + ' ms':>26}" for l in labels)
    print(head)
    for r in results:
        cells = "".join(f" {f'{ms:.1f} ({rows} legs)':>26}" for ms, rows in r["legs"].values())
        print(f"{r['engine']:<11} {r['rate']:>10.0f} {r['history_ms']:>11.2f}{cells}")
    print("goals: history of one leg < 50 ms, legs with filters < 300 ms (median of repeated queries)")
    print(f"load average while measuring: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (wall times grow with it)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
