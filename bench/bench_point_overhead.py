"""Bench: station overhead per measured point on the simulated rig at time scale 0.

Per point: move (Modbus TCP on 127.0.0.1) + settle (virtual) + interferometer read (serial pty),
through the real protocol clients, with and without HDF5 recording. Prints the median wall
time per point and the Modbus transactions per point.

Targets (issue 2 and 3): <= 2 ms and <= 3 Modbus transactions per point; a full six-leg,
361-target, six-cycle sweep (25 992 points) <= 2 ms per point including recording, file <= 10 MB.

    .venv/bin/python bench/bench_point_overhead.py [--full]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from procedures import events as ev  # noqa: E402
from procedures.plans import SweepPlan, paper_plan  # noqa: E402
from procedures.runner import CallbackSink  # noqa: E402
from station.services.config import StationConfig  # noqa: E402
from station.services.jobs import run_sweep  # noqa: E402
from station.services.wiring import open_rig  # noqa: E402


def modbus_transactions(rig) -> int:
    return next(iter(rig.axes.values())).bus.transactions


def per_point_times(rig, plan: SweepPlan, out: Path) -> tuple[list[float], int, int]:
    stamps: list[float] = []
    sink = CallbackSink(lambda e: stamps.append(time.perf_counter()) if isinstance(e, ev.PointMeasured) else None)
    tx0 = modbus_transactions(rig)
    result = run_sweep(rig, plan, out, StationConfig(), sinks=[sink])
    assert result.outcome == "completed", result.reason
    return [b - a for a, b in zip(stamps, stamps[1:])], modbus_transactions(rig) - tx0, result.points


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--full", action="store_true", help="also the 25 992-point six-leg paper sweep")
    args = ap.parse_args()
    cfg = StationConfig()
    with tempfile.TemporaryDirectory() as tmp, open_rig(cfg, legs=(1, 2, 3, 4, 5, 6), time_scale=0.0) as rig:
        plan = SweepPlan("bench", tuple(float(x) for x in range(-90, 91, 2)), cycles=3, legs=(1,), dwell_s=1.0)
        dts, tx, n = per_point_times(rig, plan, Path(tmp) / "one.h5")
        med = statistics.median(dts) * 1000
        p95 = sorted(dts)[int(0.95 * len(dts))] * 1000
        print(f"one leg, {n} points, time scale 0, Modbus TCP loopback + serial pty + HDF5 recording:")
        print(f"  median wall time per point  {med:7.3f} ms   (target <= 2 ms)   p95 {p95:.3f} ms")
        print(f"  Modbus transactions/point   {tx / n:7.2f}      (target <= 3; includes per-pass approach moves)")
        if args.full:
            plan = paper_plan()
            out = Path(tmp) / "full.h5"
            t0 = time.perf_counter()
            dts, tx, n = per_point_times(rig, plan, out)
            wall = time.perf_counter() - t0
            size_mb = out.stat().st_size / 1e6
            print(f"six legs x 361 targets x 6 cycles = {n} points:")
            print(f"  wall {wall:.1f} s = {wall / n * 1000:.3f} ms per point (target <= 2 ms); median {statistics.median(dts)*1000:.3f} ms")
            print(f"  file size {size_mb:.2f} MB (target <= 10 MB); Modbus transactions/point {tx / n:.2f}")


if __name__ == "__main__":
    main()
