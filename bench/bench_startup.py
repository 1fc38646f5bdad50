"""Bench: how fast `station` starts (issue 32, deliverable 6).

For every command, in fresh processes: CPU (user + system) and wall time of `station X --help`
and of an argument error (`station X --no-such-option`, argparse's exit 2); for `sweep` also of a
refusal (no --out) and of its first point on the simulated rig (`station sweep --sim
--time-scale 0`: the time from the command's start until its progress bar draws point 1, and
the process's CPU at that moment, all its threads, read from /proc). Beside them, in the same
run, a bare `python -c pass` (the interpreter's own start-up, which no change to the station can
remove). Each figure is the median of `--rounds` runs (default 3): the machine is shared, and
the median is the figure least moved by another job's burst.

The children run with bytecode caches, as an installed station does: PYTHONDONTWRITEBYTECODE is
dropped from their environment and every measured command is run once before it is timed.
`--no-caches` measures the other case: the station's own modules (a copy of station/, procedures/
and drivers/ first on PYTHONPATH, with PYTHONDONTWRITEBYTECODE=1) compiled from source at every
start, as in a checkout whose __pycache__ is never written; Python's and the libraries' caches kept.

Targets (issue 32): help, argument errors and refusals <= 0.3 s CPU each; the first point of a
sweep within 1 s of the command starting (wall). A figure beyond its target is marked `!`.

    .venv/bin/python bench/bench_startup.py [--rounds N] [--commands sweep,fit] [--no-caches]
"""

from __future__ import annotations

import argparse
import os
import pty
import re
import select
import shutil
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
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
CPU_TARGET_S = 0.3  # help, an argument error, a refusal
FIRST_POINT_TARGET_S = 1.0  # wall, from the command's start


def timed(argv: list[str], cwd: str) -> tuple[float, float, int]:
    """(CPU s, wall s, exit code) of one process run to its end."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=cwd, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
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
    proc = subprocess.Popen(STATION + ["sweep", "--sim", "--time-scale", "0", "--out", str(out)], cwd=cwd, env=ENV,
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


def median_of(rounds: int, measure) -> tuple[float, float]:
    """(CPU s, wall s): the medians of `rounds` measurements, after one not counted (it writes
    the bytecode caches and warms the file cache)."""
    measure()
    runs = [measure() for _ in range(rounds)]
    return statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)


def cell(figures: tuple[float, float] | None, cpu_target: float | None, wall_target: float | None = None) -> str:
    if figures is None:
        return f"{'':>13}"
    cpu, wall = figures
    late = (cpu_target is not None and cpu > cpu_target) or (wall_target is not None and wall > wall_target)
    return f"{cpu:6.2f}{wall:6.2f}{'!' if late else ' '}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--commands", help="comma-separated command names (default: all)")
    ap.add_argument("--no-caches", action="store_true", help="no bytecode caches: every module compiled at every start")
    opts = ap.parse_args()
    caches = None
    if opts.no_caches:
        caches = tempfile.TemporaryDirectory()
        for package in ("station", "procedures", "drivers"):
            shutil.copytree(REPO / package, Path(caches.name) / package, ignore=shutil.ignore_patterns("__pycache__"))
        ENV.update(PYTHONPATH=os.pathsep.join(filter(None, [caches.name, ENV.get("PYTHONPATH")])),
                   PYTHONDONTWRITEBYTECODE="1")
    names = opts.commands.split(",") if opts.commands else commands()
    rows: list[tuple[str, dict[str, tuple[float, float]]]] = []
    with tempfile.TemporaryDirectory() as cwd:
        bare = median_of(opts.rounds, lambda: timed([PYTHON, "-c", "pass"], cwd)[:2])
        for name in names:
            row = {"help": median_of(opts.rounds, lambda: timed(STATION + [name, "--help"], cwd)[:2]),
                   "error": median_of(opts.rounds, lambda: timed(STATION + [name, "--no-such-option"], cwd)[:2])}
            if name == "sweep":
                row["refusal"] = median_of(opts.rounds, lambda: timed(STATION + [name, "--sim"], cwd)[:2])
                row["first"] = median_of(opts.rounds, lambda: first_point(cwd))
            rows.append((name, row))
    load = os.getloadavg()[0]
    print(f"station start-up: CPU s and wall s, median of {opts.rounds} runs "
          f"(load average {load:.1f}, {os.cpu_count()} cores{', no bytecode caches of the station' if caches else ''}); "
          "! = beyond the target")
    print(f"targets: --help, argument error, refusal <= {CPU_TARGET_S:g} s CPU; first point <= "
          f"{FIRST_POINT_TARGET_S:g} s wall")
    print(f"{'python -c pass':<14} {cell(bare, None)}")
    heads = ("--help", "arg error", "refusal", "first point")  # refusal: sweep --sim with no --out
    print(f"{'command':<14} " + " ".join(f"{h:>12} " for h in heads))
    print(f"{'':<14} " + " ".join(f"{'CPU':>6}{'wall':>6} " for _ in heads))
    for name, row in rows:
        print(f"{name:<14} {cell(row['help'], CPU_TARGET_S)} {cell(row['error'], CPU_TARGET_S)} "
              f"{cell(row.get('refusal'), CPU_TARGET_S)} {cell(row.get('first'), None, FIRST_POINT_TARGET_S)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
