"""Recording speed and size: append per point (a journal write; /points in batches), file size of a 26 000-point session,
fsync cost, resume (rebuild) and read times. Prints figures; targets: station overhead
<= 2 ms per point including recording, a 26 000-point session <= 10 MB.

    .venv/bin/python bench/bench_recording.py [--points N] [--dir DIR]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from procedures.io.recording.reader import read_session  # noqa: E402
from procedures.io.recording.writer import SessionWriter  # noqa: E402

PAPER_POINTS = 6 * 361 * 2 * 6  # six legs, 361 targets, six bidirectional cycles = 25 992


def _record(i: int) -> dict:
    """A full point record as the sweep writes it (every field set)."""
    leg, k = divmod(i, 361 * 12)
    run, t = divmod(k, 361)
    direction = 1 if run % 2 == 0 else -1
    target = -90.0 + 0.5 * (t if direction == 1 else 360 - t)
    return dict(index=i, leg=leg + 1, run=run + 1, direction=direction, target_mm=target, commanded_mm=target,
                drive_position_mm=target + 1e-5, measured_mm=target + 2e-3, error_um=2.0 + 0.01 * (i % 97),
                time_s=3.0 * i, air_temp_c=20.1, air_pressure_hpa=1013.2, humidity_pct=45.0,
                material_temp_c=20.3, load_n=150.0, signal_pct=92.0, flags=0)


def _create(path: Path, fsync: bool = False) -> SessionWriter:
    return SessionWriter.create(path, session_id="bench", operator="bench", rig="sim",
                                plan={"kind": "paper", "targets_mm": list(np.arange(-90, 90.5, 0.5))},
                                station_config={}, devices={}, software_version="bench", fsync=fsync)


def _wchar() -> int | None:
    try:
        with open("/proc/self/io") as fh:
            return next(int(line.split()[1]) for line in fh if line.startswith("wchar"))
    except (OSError, StopIteration):
        return None


def _stats(label: str, per_point_s: np.ndarray) -> None:
    us = per_point_s * 1e6
    print(f"{label:34} mean {us.mean():7.1f} us  median {np.median(us):7.1f}  p99 {np.percentile(us, 99):7.1f}"
          f"  max {us.max():8.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=PAPER_POINTS)
    ap.add_argument("--dir", help="directory for the files (default: a temporary one)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        path = Path(tmp) / "bench.h5"
        records = [_record(i) for i in range(args.points)]
        times = np.empty(args.points)
        t_all = time.perf_counter()
        cpu0 = time.thread_time()
        with _create(path) as w:
            for i, rec in enumerate(records):
                t0 = time.perf_counter()
                w.append_point(rec)
                times[i] = time.perf_counter() - t0
            w.finish("completed")
        cpu = time.thread_time() - cpu0
        total = time.perf_counter() - t_all
        size_mb = path.stat().st_size / 1e6
        print(f"session of {args.points} points, one append_point (dict -> row bytes, journal write; every 64th writes and flushes a batch) each:")
        _stats("append_point", times)
        print(f"{'whole session (create..finish)':34} {total:.2f} s = {total / args.points * 1e3:.3f} ms per point"
              f" wall, {cpu / args.points * 1e3:.3f} ms CPU (kernel time of the writes included)")
        print(f"{'file size':34} {size_mb:.2f} MB ({path.stat().st_size / args.points:.0f} bytes per point)")

        wchar0 = _wchar()
        with _create(Path(tmp) / "io.h5") as w:
            for rec in records[:1000]:
                w.append_point(rec)
        if wchar0 is not None:
            print(f"{'bytes written per append_point':34} {(_wchar() - wchar0) / 1000:.0f} (the journal row, a share of a batch)")

        t0 = time.perf_counter()
        s = read_session(path)
        print(f"{'read_session (incl. sha256)':34} {time.perf_counter() - t0:.3f} s for {len(s.points)} points")

        # a killed file: a child writes half the points, then is killed without closing
        killed = Path(tmp) / "killed.h5"
        half = args.points // 2
        code = (
            "import sys; sys.path.insert(0, %r)\n"
            "import os, signal\n"
            "from bench.bench_recording import _create, _record\n"
            "w = _create(%r)\n"
            "w.append_points(__import__('numpy').concatenate([__import__('procedures.io.recording.writer', fromlist=['x'])"
            ".point_row(_record(i)) for i in range(%d)]))\n"
            "os.kill(os.getpid(), signal.SIGKILL)\n"
        ) % (str(Path(__file__).resolve().parents[1]), str(killed), half)
        subprocess.run([sys.executable, "-c", code], check=False)
        t0 = time.perf_counter()
        w = SessionWriter.resume(killed)
        print(f"{'resume of a killed file (rebuild)':34} {time.perf_counter() - t0:.3f} s for {w.points_written} points")
        w.close()

        fs_path = Path(tmp) / "fsync.h5"
        n_fs = min(2000, args.points)
        times = np.empty(n_fs)
        with _create(fs_path, fsync=True) as w:
            for i in range(n_fs):
                t0 = time.perf_counter()
                w.append_point(records[i])
                times[i] = time.perf_counter() - t0
        _stats(f"append_point, fsync=True ({n_fs})", times)
    load = os.getloadavg()[0]
    print(f"targets: <= 2 ms per point including recording; <= 10 MB per 26 000 points "
          f"(files in {args.dir or tempfile.gettempdir()}; load average {load:.1f} on {os.cpu_count()} CPUs)")


if __name__ == "__main__":
    main()
