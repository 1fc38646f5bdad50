"""Bench: how fast `station` starts (issue 32, deliverable 6).

For every command, in fresh processes: CPU (user + system) and wall time of `station X --help`,
of an argument error (`station X --no-such-option`, argparse's exit 2), and for `sweep` of a
refusal (no --out) and of its first point on the simulated rig (`station sweep --sim
--time-scale 0`: the time from the command's start until its progress bar draws point 1, and
the process's CPU at that moment, read from /proc). Beside them, in the same run, a bare
`python -c pass` (the interpreter's own start-up, which no change to the station can remove).
Each figure is the median of `--rounds` runs (default 3): the machine is shared, and the median
is the figure least moved by another job's burst.

Targets (issue 32): help, argument errors and refusals <= 0.3 s CPU each; the first point of a
sweep within 1 s of the command starting.

    .venv/bin/python bench/bench_startup.py [--rounds N] [--commands sweep,fit]
"""

from __future__ import annotations

import argparse
import os
import pty
import re
import select
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PYTHON = sys.executable
STATION = [PYTHON, "-c", "import sys; from station.launch import main; sys.exit(main())"]
TICKS = os.sysconf("SC_CLK_TCK")


def timed(argv: list[str], cwd: str) -> tuple[float, float, int]:
    """(CPU s, wall s, exit code) of one process run to its end."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    return usage.ru_utime + usage.ru_stime, wall, proc.returncode


def _cpu_of(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS  # utime, stime (all threads)


FIRST_POINT = re.compile(rb"\b1/\d+\b")


def first_point(cwd: str) -> tuple[float, float]:
    """(CPU s, wall s) from the start of `station sweep --sim --time-scale 0` until its progress
    bar (stderr on a terminal: it draws the first point at once) shows point 1."""
    out = Path(cwd) / "first.h5"
    out.unlink(missing_ok=True)
    master, slave = pty.openpty()
    t0 = time.perf_counter()
    proc = subprocess.Popen(STATION + ["sweep", "--sim", "--time-scale", "0", "--out", str(out)], cwd=cwd,
                            stdout=subprocess.DEVNULL, stderr=slave, stdin=subprocess.DEVNULL)
    os.close(slave)
    seen = b""
    wall = cpu = float("nan")
    try:
        while time.perf_counter() - t0 < 60:
            ready, _, _ = select.select([master], [], [], 1.0)
            if not ready:
                if proc.poll() is not None:
                    break
                continue
            try:
                chunk = os.read(master, 4096)
            except OSError:
                break
            if not chunk:
                break
            seen += chunk
            if FIRST_POINT.search(seen):
                wall = time.perf_counter() - t0
                cpu = _cpu_of(proc.pid)
                break
    finally:
        proc.terminate()  # the rest of the sweep is not what is measured
        proc.wait()
        os.close(master)
    if wall != wall:
        raise RuntimeError(f"no first point seen; the sweep said: {seen.decode(errors='replace')[-500:]}")
    return cpu, wall


def commands() -> list[str]:
    from station.cli import _command_specs

    return sorted(_command_specs())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--commands", help="comma-separated command names (default: all)")
    opts = ap.parse_args()
    names = opts.commands.split(",") if opts.commands else commands()
    rows: list[tuple[str, str, list[tuple[float, float]]]] = []
    with tempfile.TemporaryDirectory() as cwd:
        rows.append(("python -c pass", "", [timed([PYTHON, "-c", "pass"], cwd)[:2] for _ in range(opts.rounds)]))
        for name in names:
            rows.append((name, "--help", [timed(STATION + [name, "--help"], cwd)[:2] for _ in range(opts.rounds)]))
            rows.append((name, "argument error", [timed(STATION + [name, "--no-such-option"], cwd)[:2]
                                                  for _ in range(opts.rounds)]))
            if name == "sweep":
                rows.append((name, "refusal (no --out)", [timed(STATION + [name, "--sim"], cwd)[:2]
                                                          for _ in range(opts.rounds)]))
                rows.append((name, "first point", [first_point(cwd) for _ in range(opts.rounds)]))
    load = os.getloadavg()[0]
    print(f"station start-up, median of {opts.rounds} runs (load average {load:.1f}, {os.cpu_count()} cores)")
    print(f"{'command':<14} {'what':<20} {'CPU s':>7} {'wall s':>7}")
    for name, what, runs in rows:
        cpu = statistics.median(r[0] for r in runs)
        wall = statistics.median(r[1] for r in runs)
        target = 1.0 if what == "first point" else 0.3
        mark = "" if not what else ("" if (wall if what == "first point" else cpu) <= target else "  > target")
        print(f"{name:<14} {what:<20} {cpu:7.2f} {wall:7.2f}{mark}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
