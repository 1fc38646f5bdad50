"""Bench: replay of the six-leg sample calibration at full speed, recorded again, against the
same replay by the station before issue 26's overhead work (goal: at least 2x, identical).

The replay goes through everything a live sweep does: Modbus TCP on 127.0.0.1 to the replay
drives, the serial client over a pty to the replay interferometer, the sweep procedure, the
runner and the HDF5 recorder. Prints points per second, the wall time, the protocol
transactions per point, and whether the new session equals the recording. Each round is
followed by the same replay by commit BASELINE's tree (its own bench_replay.py, run from a
`git archive` of it in a temporary directory with this interpreter: same venv, same machine,
the same moment's load), and the speed-up is printed round by round, then min / median / max.
On a loaded machine a point's wall time is mostly the hand-overs between the station's thread
and the replay devices' threads (a request, a reply: the scheduler's), so the rounds scatter.

Measured 2026-11-27 (2 cores, other jobs running, load average 4.3-5.2; three runs of two
rounds): 1667-2554 points/s against the baseline's 794-1275; speed-up per run 1.77 / 1.92 /
2.30x (min / median / max), the six rounds 1.62-2.59x; every replay identical. At load 3:
3306-4368 points/s, 1.62 and 2.51x. On the same box with nothing else running (load average
0.4-1.0, two runs of three rounds): 1957-2051 points/s against 1167-1217, 1.64 / 1.66-1.69 /
1.70x: the goal of 2 was met only under load; a replayed point was then mostly the replay
drive's pymodbus server. With the simulated drive's own Modbus TCP server
(drivers/sim/modbus_tcp.py) and a leaner drive model, same box, load average 0.9-1.0, three
runs of three rounds: 2481-2716 points/s against 1193-1317, speed-up 2.08 / 2.13 / 2.17,
2.09 / 2.11 / 2.16 and 1.99 / 2.17 / 2.26x (min / median / max per run); every replay
identical. docs/replay.md says where the time went.

    .venv/bin/python bench/bench_replay.py [--session recordings/calibration-6legs.h5] [--speed max]
        [--rounds N] [--baseline REV] [--old]
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
# sessions in temporary folders, of no leg: not for the station's catalog (whose indexing thread
# would find them gone)
os.environ.setdefault("STATION_CATALOG", "off")

import numpy as np  # noqa: E402

from procedures.io.recording.reader import read_session  # noqa: E402
from procedures.acquisition.replay_compare import compare_sessions  # noqa: E402
from station.commands.replay import parse_speed  # noqa: E402
from station.services.jobs import replay_sweep  # noqa: E402
from station.services.config import StationConfig  # noqa: E402
from station.services.wiring import open_replay_rig  # noqa: E402

DEFAULT = Path(__file__).resolve().parents[1] / "recordings" / "calibration-6legs.h5"


def device_round_trips(path: Path, cfg: StationConfig) -> tuple[float, float, float, int]:
    """Median ms of a move, a position reading and an environment reading on the replay devices,
    over leg 1's first two passes (the protocol part of a point, without runner and recorder)."""
    session = read_session(path)
    pts = session.points[(session.points["leg"] == 1) & (session.points["run"] <= 2)]
    pts = pts[np.argsort(pts["index"])]
    with open_replay_rig(path, None, cfg, legs=(1,)) as rig:
        axis, laser = rig.axes[1], rig.laser
        axis.enable()
        laser.set_averaging(0.1)
        tm, tr, te = [], [], []
        run = None
        for p in pts:
            if p["run"] != run:  # a new pass: approach from its side, as the sweep does
                run = p["run"]
                axis.move_to(float(p["target_mm"]) - int(p["direction"]) * 2.0)
            t0 = time.perf_counter()
            axis.move_to(float(p["target_mm"]))
            t1 = time.perf_counter()
            laser.read(1)
            t2 = time.perf_counter()
            laser.environment()
            t3 = time.perf_counter()
            tm.append(t1 - t0), tr.append(t2 - t1), te.append(t3 - t2)
    ms = lambda xs: statistics.median(xs) * 1000.0  # noqa: E731
    return ms(tm), ms(tr), ms(te), len(pts)


def old_path(session, path: Path, speed, cfg: StationConfig) -> tuple[float, int, bool]:
    """Points per second, interferometer exchanges and identity of the replay by the old path:
    the environment asked at every point (no recorded point counted as unchanged)."""
    import station.services.jobs as jobs

    kept = jobs.env_unchanged_at
    jobs.env_unchanged_at = lambda points: frozenset()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "old.h5"
            with open_replay_rig(path, speed, cfg) as rig:
                lx0 = rig.laser.transactions
                t0 = time.perf_counter()
                result = replay_sweep(rig, session, out, cfg)
                wall = time.perf_counter() - t0
                lx = rig.laser.transactions - lx0
            same = compare_sessions(session, read_session(out)).identical
    finally:
        jobs.env_unchanged_at = kept
    return result.points / wall, lx, same


BASELINE = "c28ae05"
"""The station before issue 26's software-overhead work: "today's" replay of the issue."""


def baseline_rate(rev: str, session: Path, speed: str) -> float | None:
    """Points per second of the same replay by the code of commit `rev`: its own
    bench/bench_replay.py, run from a `git archive` of it in a temporary directory with this
    interpreter (same venv, same machine, same moment). None when git or the commit is absent."""
    root = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        try:
            archive = subprocess.run(["git", "-C", str(root), "archive", rev], capture_output=True, timeout=120)
        except (OSError, subprocess.TimeoutExpired):
            return None
        if archive.returncode:
            return None
        subprocess.run(["tar", "-x", "-C", tmp], input=archive.stdout, check=True)
        out = subprocess.run([sys.executable, "bench/bench_replay.py", "--no-old", "--session", str(session.resolve()),
                              "--speed", speed], cwd=tmp, capture_output=True, text=True, timeout=600)
    m = re.search(r"([0-9.]+) points/s", out.stdout)
    return float(m.group(1)) if m else None


def replay_once(path: Path, session, speed, cfg: StationConfig):
    """One replay by this tree: (points per second, wall s, result, Modbus and interferometer
    transactions, mismatch, comparison, new file's MB, open s)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "replay.h5"
        t_open = time.perf_counter()
        with open_replay_rig(path, speed, cfg) as rig:
            t_open = time.perf_counter() - t_open
            bus = next(iter(rig.axes.values())).bus
            tx0, lx0 = bus.transactions, rig.laser.transactions
            t0 = time.perf_counter()
            result = replay_sweep(rig, session, out, cfg)
            wall = time.perf_counter() - t0
            tx, lx = bus.transactions - tx0, rig.laser.transactions - lx0
            mismatch = rig.sim.mismatch
        cmp = compare_sessions(session, read_session(out))
        size_mb = out.stat().st_size / 1e6
    return result.points / wall, wall, result, tx, lx, mismatch, cmp, size_mb, t_open


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--session", type=Path, default=DEFAULT, help="session to replay (default: the six-leg sample)")
    ap.add_argument("--speed", default="max", help="1, N or max (default max)")
    ap.add_argument("--rounds", type=int, default=3, help="replays by this tree, each followed by one by the baseline")
    ap.add_argument("--baseline", default=BASELINE, help=f"commit to compare with (default {BASELINE}); '' for none")
    ap.add_argument("--old", action="store_true", help="also the environment-at-every-point path of this tree")
    ap.add_argument("--no-old", action="store_true", help=argparse.SUPPRESS)  # what older trees' benches take
    args = ap.parse_args()
    speed = parse_speed(args.speed)
    cfg = StationConfig(operator="bench")
    t_read = time.perf_counter()
    session = read_session(args.session)
    t_read = time.perf_counter() - t_read
    rates, base_rates = [], []
    for k in range(max(1, args.rounds)):
        rate, wall, result, tx, lx, mismatch, cmp, size_mb, t_open = replay_once(args.session, session, speed, cfg)
        rates.append(rate)
        n = result.points
        if k == 0:
            recorded_h = float(session.points["time_s"].max()) / 3600.0
            print(f"replay of {args.session.name}: {n} points, {len(session.plan.get('legs', []))} legs, "
                  f"{recorded_h:.2f} h recorded, speed {args.speed}")
            print(f"  open: read {t_read:.2f} s, rig + clients {t_open:.2f} s; new session {size_mb:.2f} MB")
            print(f"  per point: {tx / n:.2f} Modbus transactions, {lx / n:.2f} interferometer exchanges")
        print(f"  round {k + 1}: {rate:8.1f} points/s   ({wall:.1f} s wall, {wall / n * 1000:.3f} ms per point; "
              f"{recorded_h * 3600 / wall:.0f}x real time); outcome {result.outcome}; mismatch {mismatch}; "
              f"identical to the recording: {cmp.identical}"
              + ("" if cmp.identical else f" ({'; '.join(cmp.differences)})"))
        if args.baseline:
            base = baseline_rate(args.baseline, args.session, args.speed)
            if base is None:
                print(f"  baseline {args.baseline}: not available (no git, or no such commit)")
                args.baseline = ""
            else:
                base_rates.append(base)
                print(f"           baseline {args.baseline} (its own bench, same run): {base:8.1f} points/s; "
                      f"this / baseline {rate / base:.2f}x")
    print(f"  points/s min / median / max: {min(rates):.1f} / {statistics.median(rates):.1f} / {max(rates):.1f}"
          f"   (load average {' '.join(f'{x:.2f}' for x in os.getloadavg())})")
    if base_rates:
        ratios = [a / b for a, b in zip(rates, base_rates)]
        print(f"  speed-up over {args.baseline}, round by round, min / median / max: "
              f"{min(ratios):.2f} / {statistics.median(ratios):.2f} / {max(ratios):.2f}x   (goal >= 2)")
    if args.old:
        old_rate, old_lx, old_same = old_path(session, args.session, speed, cfg)
        print(f"  environment asked at every point (this tree): {old_rate:8.1f} points/s, "
              f"{old_lx / n:.2f} interferometer exchanges per point, identical: {old_same}")
    move_ms, read_ms, env_ms, k = device_round_trips(args.session, cfg)
    print(f"  replay devices alone ({k} points of leg 1, medians): move {move_ms:.3f} ms (Modbus TCP), "
          f"position {read_ms:.3f} ms, environment {env_ms:.3f} ms (pty)")


if __name__ == "__main__":
    main()
