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
    from station.progress import ConsoleProgress
    from station.services.replay_job import ReplayRequest, prepare_replay

    job = prepare_replay(ReplayRequest(Path(args.session), Path(args.out) if args.out else None, args.speed,
                                       args.force))
    for line in job.lines:
        print(line)
    outcome = job.run(sinks=[ConsoleProgress()])
    ended = outcome.data
    print(outcome.lines[0])
    if ended.mismatch is not None:
        raise ended.mismatch
    for line in outcome.lines[1:]:
        print(line)
    return 0 if ended.comparison.identical else 1
