"""Bench: a soak session. One long sweep (six legs, the paper's 361 targets, as many cycles as it
takes to pass --points) on the simulated rig at time scale 0, through the faulty link of
tests/faults (Modbus proxy and interferometer line faults on the rig clock, one on each link
every --every-s seconds of rig time on average). A sweep the faults stop is resumed, as
`station sweep --resume` would, until the session is complete.

Prints resident memory (VmRSS), open file descriptors and threads over the run, the growth of
memory after warm-up (the first --warmup fraction of the points), the faults injected per kind,
and checks the file: read back with the station's reader, complete (every planned point once),
outcome completed, every acknowledged point in it with its value. Not a test (timings and a
day of rig time have no place in CI); exit code 1 when a check fails.

    .venv/bin/python bench/bench_soak.py [--points 200000] [--every-s 180] [--seed 0] [--out FILE.h5]
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
# sessions in temporary folders, of no leg: not for the station's catalog (whose indexing thread
# would find them gone)
os.environ.setdefault("STATION_CATALOG", "off")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from procedures.engine import events as ev  # noqa: E402
from procedures.acquisition.plans import paper_plan  # noqa: E402
from procedures.io.recording.reader import read_session  # noqa: E402
from procedures.engine.runner import CallbackSink  # noqa: E402
from station.services.config import StationConfig  # noqa: E402
from station.services.jobs import run_sweep  # noqa: E402
from tests.faults.rigs import faulty_rig  # noqa: E402

TARGETS_PER_PASS = 361
LEGS = (1, 2, 3, 4, 5, 6)


def proc_status() -> dict[str, int]:
    """VmRSS (kB) and Threads of this process, from /proc/self/status."""
    out = {}
    with open("/proc/self/status") as fh:
        for line in fh:
            key, _, value = line.partition(":")
            if key in ("VmRSS", "Threads"):
                out[key] = int(value.split()[0])
    return out


def fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=200_000, help="at least this many points (default 200000)")
    ap.add_argument("--every-s", type=float, default=180.0, help="mean rig seconds between faults on each link")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--warmup", type=float, default=0.1, help="fraction of the points counted as warm-up")
    ap.add_argument("--samples", type=int, default=20, help="memory samples printed")
    ap.add_argument("--out", type=Path, help="session file (default: in a temporary directory, removed)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)  # the sweep's warnings about each retried fault: counted, not shown

    cycles = max(1, math.ceil(args.points / (TARGETS_PER_PASS * 2 * len(LEGS))))
    plan = paper_plan(LEGS, cycles=cycles)
    total = plan.total_points
    tmp = None if args.out else tempfile.TemporaryDirectory(prefix="soak-")
    out = args.out or Path(tmp.name) / "soak.h5"
    if out.exists():
        print(f"{out}: exists; give a new file", file=sys.stderr)
        return 2
    # what the station acknowledged (recorded and flushed), preallocated so the bench itself does not grow
    acked = np.zeros(total, dtype=bool)
    acked_error = np.full(total, np.nan)
    every = max(1, total // args.samples)
    warm_at = int(total * args.warmup)
    rows: list[tuple] = []
    t_wall0 = time.monotonic()

    print(f"soak: {total} points ({cycles} cycles x {TARGETS_PER_PASS} targets x 2 directions x {len(LEGS)} legs), "
          f"time scale 0, a fault on each link every {args.every_s:g} rig s on average, seed {args.seed}")
    before = {"fds": fds(), "threads": threading.active_count(), "os_threads": proc_status()["Threads"]}
    rig, link = faulty_rig(seed=args.seed, every_s=args.every_s, legs=LEGS)
    start = {"rss_kb": proc_status()["VmRSS"], "fds": fds(), "threads": threading.active_count(),
             "os_threads": proc_status()["Threads"]}
    counter = {"n": 0}

    def on_event(e) -> None:
        if isinstance(e, ev.PointMeasured):
            i = int(e.record["index"])
            acked[i] = True
            acked_error[i] = e.record["error_um"]
            counter["n"] += 1
            n = counter["n"]
            if n % every == 0 or n == warm_at:
                st = proc_status()
                rows.append((n, rig.clock.now() / 3600.0, time.monotonic() - t_wall0, st["VmRSS"] / 1024.0, fds(),
                             threading.active_count(), st["Threads"], link.counts.total()))
                r = rows[-1]
                print(f"  {r[0]:>8} {r[1]:>9.2f} {r[2]:>8.0f} {r[3]:>8.1f} {r[4]:>4} {r[5]:>4} {r[6]:>4} {r[7]:>6}", flush=True)

    print(f"  {'points':>8} {'rig h':>9} {'wall s':>8} {'RSS MB':>8} {'fds':>4} {'thr':>4} {'os':>4} {'faults':>6}")
    resumes = 0
    outcome = ""
    try:
        link.arm()
        cfg = StationConfig()
        while True:
            result = run_sweep(rig, plan, out, cfg, sinks=[CallbackSink(on_event)], resume=resumes > 0)
            outcome = str(result.outcome)
            if outcome == "completed" or resumes >= 10_000:
                break
            resumes += 1
        link.arm(False)
        rig_h = rig.clock.now() / 3600.0
        faults = dict(sorted(link.counts.items()))
    finally:
        rig.close()
    wall = time.monotonic() - t_wall0
    end = {"rss_kb": proc_status()["VmRSS"], "fds": fds(), "threads": threading.active_count(),
           "os_threads": proc_status()["Threads"]}

    s = read_session(out)
    idx = s.points["index"]
    complete = len(idx) == total and np.array_equal(np.sort(idx), np.arange(total))
    in_file = np.zeros(total, dtype=bool)
    in_file[idx] = True
    lost = int(np.count_nonzero(acked & ~in_file))
    order = np.argsort(idx)
    changed = int(np.count_nonzero(s.points["error_um"][order][acked] != acked_error[acked])) if complete else -1

    warm = [r for r in rows if r[0] >= warm_at]
    base = warm[0][3] if warm else float("nan")
    peak = max(r[3] for r in warm) if warm else float("nan")
    last = warm[-1][3] if warm else float("nan")
    print(f"rig time {rig_h:.1f} h in {wall / 60:.1f} min wall ({wall / total * 1000:.2f} ms per point), "
          f"{resumes} resumes, outcome {outcome}")
    print(f"faults injected: {sum(faults.values())} ({', '.join(f'{k} {v}' for k, v in faults.items())})")
    print(f"resident memory: start {start['rss_kb'] / 1024:.1f} MB, after warm-up ({warm_at} points) {base:.1f} MB, "
          f"peak {peak:.1f} MB, end of sweep {last:.1f} MB: growth after warm-up {100 * (peak - base) / base:+.1f} % (peak), "
          f"{100 * (last - base) / base:+.1f} % (end); limit 10 %")
    during = [r for r in warm] or rows
    print(f"file descriptors: {before['fds']} before the rig, {start['fds']} with it, {min(r[4] for r in during)}.."
          f"{max(r[4] for r in during)} during the sweep after warm-up, {end['fds']} after closing it")
    print(f"threads (Python / OS): {before['threads']} / {before['os_threads']} before the rig, {start['threads']} / "
          f"{start['os_threads']} with it, {min(r[5] for r in during)}..{max(r[5] for r in during)} / "
          f"{min(r[6] for r in during)}..{max(r[6] for r in during)} during the sweep after warm-up, "
          f"{end['threads']} / {end['os_threads']} after closing it")
    print(f"file {out}: {out.stat().st_size / 1e6:.1f} MB, {len(idx)} of {total} points, outcome {s.outcome}, "
          f"{len(s.faults)} fault rows, {len(s.resumed_utc)} resumes recorded; acknowledged {int(acked.sum())}, "
          f"lost {lost}, changed {changed}")
    checks = {
        "file complete, outcome completed": complete and s.outcome == "completed",
        "no acknowledged point lost or changed": lost == 0 and changed == 0,
        "memory growth after warm-up < 10 %": (peak - base) / base < 0.10,
        "no fd growth during the sweep (a reconnect in flight holds at most 2)":
            max(r[4] for r in during) - min(r[4] for r in during) <= 2 and end["fds"] <= before["fds"],
        "no thread growth (a connection's thread in flight: at most 2)":
            max(r[6] for r in during) - min(r[6] for r in during) <= 2 and end["os_threads"] <= before["os_threads"],
    }
    if args.points >= 200_000:
        checks["at least 24 h of rig time"] = rig_h >= 24.0
    for name, passed in checks.items():
        print(f"  {'ok  ' if passed else 'FAIL'} {name}")
    ok = all(checks.values())
    print("soak checks:", "PASS" if ok else "FAIL")
    if tmp is not None:
        tmp.cleanup()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
