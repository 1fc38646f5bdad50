"""`station run`: the main job on the simulated rig, headless.

An ISO 230-2 sweep of one leg on the simulated rig (through the real Modbus and serial
protocols), recorded to runs/, followed by its ISO 230-2 evaluation. This is the scriptable,
non-interactive main job; `station` with no arguments starts the terminal UI. The sweep is the
job `station sweep` runs (station/services/sweep_job.py), prepared and run the same way.
"""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse

NAME = "run"
HELP = "headless calibration sweep on the simulated rig, then its ISO 230-2 evaluation"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--legs", type=V.LEGS.argtype(), default="1", help="legs to sweep (default 1)")
    p.add_argument("--cycles", type=V.CYCLES.argtype(), default=5, help="bidirectional cycles (default 5)")
    p.add_argument("--out", type=V.OUT_FILE.argtype(), help="session file (default runs/run-YYYYmmdd-HHMMSS.h5)")
    p.add_argument("--time-scale", type=V.TIME_SCALE.argtype(), default=0.0, help="real s per simulated s (default 0: no waiting)")


def run(args) -> int:
    from station.services.config import load_config
    from station.commands._rig_cli import run_on_rig
    from procedures.vocabulary import InputError
    from station.services.sweep_job import OutputExists, SweepRequest, iso230_lines, prepare_sweep

    cfg = load_config(None)
    try:
        job = prepare_sweep(SweepRequest(out=args.out, legs=args.legs, kind="iso230", cycles=args.cycles,
                                         time_scale=args.time_scale, default_out_prefix="run", make_parents=True), cfg)
    except OutputExists:
        raise InputError(f"--out {args.out}: exists; choose another --out; nothing was written") from None
    ended, _ = run_on_rig(job, sim_memory=False)  # the simulated rig: no table to ask about
    print(f"session recorded: {job.out.resolve()} ({ended.status}, {ended.points} points)")
    if ended.status != "completed":
        return 1
    for line in iso230_lines(job.out):
        print(line)
    return 0
