"""`station replay`: run a recorded session's plan again against replay devices, and record it.

The replay devices answer from the recording over the real Modbus and serial protocols
(docs/replay.md), and the plan runs through the normal sweep procedure and runner, so the new
session is made exactly as a live one is, with rig kind "replay" and every point flagged
FLAG_REPLAYED. Afterwards the new session is compared with the original, field by field.
"""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
from pathlib import Path

from procedures.vocabulary import InputError

NAME = "replay"
HELP = "replay a recorded session through the same drivers and record it again (--speed 1|N|max)"
DESCRIPTION = (
    "Run the plan stored in FILE.h5 through the normal sweep procedure against replay devices "
    "that answer from the recording over the real Modbus and serial protocols: readings, "
    "environment, loads, faults and timing all come from the recording. The new session "
    "(rig 'replay', points flagged as replayed) is compared with the original field by field; "
    "analysing it gives the same results. See docs/replay.md."
)


def parse_speed(text: str) -> float | None:
    """station.services.jobs.parse_speed for argparse: its message as an ArgumentTypeError."""
    from station.services import jobs

    try:
        return jobs.parse_speed(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("session", type=V.SESSION.argtype(), metavar="FILE.h5", help="recorded session to replay")
    p.add_argument("--speed", type=V.REPLAY_SPEED.argtype(), default=None, metavar="1|N|max",
                   help="1 = real time, N = N times faster, max = as fast as possible (default max)")
    p.add_argument("--out", type=V.OUT_FILE.argtype(), metavar="NEW.h5", help="session file to record (default FILE.replay.h5 beside FILE)")
    p.add_argument("--force", action="store_true", help="replace --out if it exists (default: refused)")


# -- the command -----------------------------------------------------------------------------------

def run(args) -> int:
    from procedures.io.recording.reader import read_session
    from procedures.io.outputs import check_output_file
    from station.services.config import load_config
    from station.progress import ConsoleProgress
    from station.services.jobs import replay_and_compare

    source = Path(args.session)
    session = read_session(source)
    out = Path(args.out) if args.out else source.with_name(source.stem + ".replay.h5")
    if out.resolve() == source.resolve():
        raise InputError(f"--out {out} is the recording being replayed; choose another file")
    check_output_file(out, force=args.force, suffixes=(".h5",))
    if not session.plan:
        raise InputError(f"{source}: the session stores no sweep plan, so there is nothing to replay")
    cfg = load_config(None)
    pace = "as fast as possible" if args.speed is None else ("real time" if args.speed == 1 else f"{args.speed:g}x real time")
    print(f"replaying {source} ({len(session.points)} points, outcome {session.outcome}) {pace}")
    if args.force and out.exists():
        out.unlink()  # --force: the new replay session replaces it
    ended = replay_and_compare(source, session, out, cfg, args.speed, sinks=[ConsoleProgress()])
    result = ended.result
    print(f"session: {out} ({result.outcome}, {result.points} points; rig replay)")
    if ended.mismatch is not None:
        raise ended.mismatch
    cmp = ended.comparison
    if cmp.identical:
        print(f"identical to the recording: {cmp.points} points (all fields), {cmp.faults} faults, outcome {result.outcome}")
        print(f"next: station fit {out} --out model.json   (gives the model of {source})")
        return 0
    print("differs from the recording:")
    for line in cmp.differences:
        print(f"  {line}")
    return 1

