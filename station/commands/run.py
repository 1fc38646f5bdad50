"""`station run`: the main job on the simulated rig, headless.

An ISO 230-2 sweep of one leg on the simulated rig (through the real Modbus and serial
protocols), recorded to runs/, followed by its ISO 230-2 evaluation. This is the scriptable,
non-interactive main job; `station` with no arguments starts the terminal UI.
"""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse

from procedures.io.outputs import check_output_file
from procedures.engine.control import RunControl
from procedures.vocabulary import Outcome
from station.interrupt import abort_on_sigint
from station.progress import ConsoleProgress

NAME = "run"
HELP = "headless calibration sweep on the simulated rig, then its ISO 230-2 evaluation"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--legs", type=V.LEGS.argtype(), default="1", help="legs to sweep (default 1)")
    p.add_argument("--cycles", type=V.CYCLES.argtype(), default=5, help="bidirectional cycles (default 5)")
    p.add_argument("--out", type=V.OUT_FILE.argtype(), help="session file (default runs/run-YYYYmmdd-HHMMSS.h5)")
    p.add_argument("--time-scale", type=V.TIME_SCALE.argtype(), default=0.0, help="real s per simulated s (default 0: no waiting)")


def run(args) -> int:
    from procedures.acquisition.plan_spec import PlanSpec, plan_from_spec
    from procedures.acquisition.plans import parse_legs
    from station.commands.sweep import check_time_scale
    from station.services.config import load_config
    from station.services.jobs import run_sweep
    from station.services.sessions import default_session_path
    from station.services.wiring import open_rig

    cfg = load_config(None)
    plan = plan_from_spec(PlanSpec(legs=parse_legs(args.legs), kind="iso230", cycles=args.cycles), cfg.limits)
    check_time_scale(args.time_scale)
    out = check_output_file(args.out or default_session_path(cfg, prefix="run"), suffixes=(".h5",), make_parents=True)
    with open_rig(cfg, legs=plan.legs, time_scale=args.time_scale) as rig:
        print(f"rig: {rig.description}")
        with abort_on_sigint(RunControl()) as control:
            result = run_sweep(rig, plan, out, cfg, sinks=[ConsoleProgress()], control=control)
    print(f"session recorded: {out.resolve()} ({result.outcome}, {result.points} points)")
    if result.outcome != Outcome.COMPLETED:
        return 1
    from procedures.reporting.iso230 import evaluate, format_table
    from procedures.io.recording.reader import read_session
    from procedures.metrology.thermal import error_basis
    from station.services.report_jobs import iso_lines, session_iso230

    session = read_session(out)
    points, basis_lines, _ = error_basis(session, False)  # as station iso230 / fit: normalised to 20 degC
    for line in basis_lines:
        print(line)
    print(format_table(evaluate(points)))
    for line in iso_lines(session_iso230(session)):  # each value with its expanded uncertainty U (k = 2)
        print(line)
    return 0
