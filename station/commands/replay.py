"""`station replay`: run a recorded session's plan again against replay devices, and record it.

The replay devices answer from the recording over the real Modbus and serial protocols
(docs/replay.md), and the plan runs through the normal sweep procedure and runner, so the new
session is made exactly as a live one is, with rig kind "replay" and every point flagged
FLAG_REPLAYED. Afterwards the new session is compared with the original, field by field.
"""

from __future__ import annotations

import argparse
import math
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

import numpy as np

from procedures import events as ev
from procedures.control import RunControl
from procedures.errors import InputError
from procedures.plans import SweepPlan
from procedures.recording.reader import Session, read_session
from procedures.recording.schema import FLAG_REPLAYED
from procedures.recording.sink import RecorderSink
from procedures.runner import RunResult, Sink, run as run_procedure
from procedures.sweep import RetryPolicy, sweep
from station import __version__
from station.config import StationConfig
from station.wiring import Rig

NAME = "replay"
HELP = "replay a recorded session through the same drivers and record it again (--speed 1|N|max)"
DESCRIPTION = (
    "Run the plan stored in FILE.h5 through the normal sweep procedure against replay devices "
    "that answer from the recording over the real Modbus and serial protocols: readings, "
    "environment, loads, faults and timing all come from the recording. The new session "
    "(rig 'replay', points flagged as replayed) is compared with the original field by field; "
    "analysing it gives the same results. See docs/replay.md."
)

_KIND_LIMIT = {"beam_break": "beam_retries", "drive_fault": "drive_retries"}  # other kinds: comm_retries


def parse_speed(text: str) -> float | None:
    """'max' -> None (as fast as possible); '1' -> real time; '10' -> ten times faster."""
    t = str(text).strip().lower()
    if t in ("max", "inf", "fastest"):
        return None
    try:
        value = float(t)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give a speed factor (1 = real time, 10 = ten times faster) or 'max'") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r}: the speed factor must be > 0 (or 'max')")
    return value


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("session", metavar="FILE.h5", help="recorded session to replay")
    p.add_argument("--speed", type=parse_speed, default=None, metavar="1|N|max",
                   help="1 = real time, N = N times faster, max = as fast as possible (default max)")
    p.add_argument("--out", metavar="NEW.h5", help="session file to record (default FILE.replay.h5 beside FILE)")


# -- the job (both front ends) -------------------------------------------------------------------

def retry_policy_of(session: Session, base: RetryPolicy = RetryPolicy()) -> RetryPolicy:
    """The retry limits the recorded run must have had: a fault that gave up at attempt n means
    a limit of n - 1 for its kind; a fault that did not give up at attempt n means at least n.
    The environment is read at every point, so each replayed point gets the environment recorded
    with it, whatever the recorded run's reading interval was (`env_interval_s` is -inf rather than
    0 because the recorded clock restarts in a resumed session, and the sweep compares `now -
    last reading` with it)."""
    limits = {"beam_retries": base.beam_retries, "drive_retries": base.drive_retries, "comm_retries": base.comm_retries}
    exact: dict[str, int] = {}
    for row in session.faults:
        kind = row["kind"].decode("utf-8", "replace") if isinstance(row["kind"], bytes) else str(row["kind"])
        name = _KIND_LIMIT.get(kind, "comm_retries")
        attempt = int(row["attempt"])
        if row["gave_up"]:
            exact[name] = attempt - 1
        else:
            limits[name] = max(limits[name], attempt)
    limits.update(exact)
    return RetryPolicy(beam_retries=limits["beam_retries"], drive_retries=limits["drive_retries"],
                       comm_retries=limits["comm_retries"], beam_wait_s=base.beam_wait_s, env_interval_s=-math.inf)


class ReplayRecorderSink(RecorderSink):
    """The recorder sink, with FLAG_REPLAYED set on every point it writes."""

    def handle(self, event: ev.Event) -> None:
        if isinstance(event, ev.PointMeasured):
            record = dict(event.record)
            record["flags"] = int(record.get("flags", 0)) | FLAG_REPLAYED
            event = ev.PointMeasured(record, event.done, event.total)
        super().handle(event)


def replay_sweep(
    rig: Rig,
    session: Session,
    out: str | Path,
    cfg: StationConfig | None = None,
    sinks: Iterable[Sink] = (),
    control: RunControl | None = None,
) -> RunResult:
    """Run `session`'s plan on the replay `rig` (station.wiring.open_replay_rig) through the
    sweep procedure and the runner, recording to `out` (rig kind "replay").

    Where the recording was cut short (aborted, killed), the run is aborted where the recording
    ends; a recorded give-up ends it "failed" at the same point. If a device met a request the
    recording does not hold, `rig.sim.mismatch` names the first one (the run then fails).
    """
    if rig.kind != "replay":
        raise InputError(f"replay_sweep needs a replay rig (station.wiring.open_replay_rig), not a {rig.kind} rig")
    cfg = cfg or StationConfig()
    control = control or RunControl()
    plan = SweepPlan.from_dict(session.plan)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rig.sim.on_end = lambda reason: control.abort(reason)
    control.on_abort(rig.clock.cancel_waits)
    recorder = ReplayRecorderSink(out, operator=cfg.operator, rig="replay", station_config=cfg.to_dict(),
                                  software_version=__version__)
    # t0_s=0: recorded times are seconds since the session start, so `now - 0` is bit-exact
    procedure = sweep(plan, rig.axes, rig.laser, rig.clock, control=control, retry=retry_policy_of(session),
                      session_id=uuid.uuid4().hex[:12], t0_s=0.0)
    return run_procedure(procedure, [recorder, *sinks], control)


# -- comparing a replay with its recording ---------------------------------------------------------

@dataclass(frozen=True)
class Comparison:
    """How a replayed session differs from its recording. `differences` is empty when every
    point field (flags apart from FLAG_REPLAYED), every fault and the outcome are identical."""

    points: int
    faults: int
    differences: tuple[str, ...]

    @property
    def identical(self) -> bool:
        return not self.differences


def _same(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Element-wise bit-identity, NaN equal to NaN (an unknown value stays unknown)."""
    if a.dtype.kind == "f":
        return (a == b) | (np.isnan(a) & np.isnan(b))
    return a == b


def compare_sessions(original: Session, replayed: Session) -> Comparison:
    """Compare a replay with its recording point by point (matched by plan index)."""
    diffs: list[str] = []
    po, pr = original.points, replayed.points
    if len(po) != len(pr):
        diffs.append(f"{len(pr)} points replayed, the recording has {len(po)}")
    o = po[np.argsort(po["index"], kind="stable")]
    r = pr[np.argsort(pr["index"], kind="stable")]
    n = min(len(o), len(r))
    o, r = o[:n], r[:n]
    for name in po.dtype.names:
        a, b = o[name], r[name]
        if name == "flags":
            a = a | FLAG_REPLAYED
        bad = np.flatnonzero(~_same(a, b))
        if bad.size:
            i = int(bad[0])
            diffs.append(f"{name} differs at {bad.size} point(s), first at index {int(o['index'][i])}: "
                         f"recorded {a[i]!r}, replayed {b[i]!r}")
    fo, fr = original.faults, replayed.faults
    keys = ("index", "leg", "run", "target_mm", "time_s", "kind", "attempt", "gave_up")
    if len(fo) != len(fr):
        diffs.append(f"{len(fr)} faults replayed, the recording has {len(fo)}")
    for i, (a, b) in enumerate(zip(fo, fr)):
        bad = [k for k in keys if not bool(_same(np.asarray(a[k]), np.asarray(b[k])))]
        if bad:
            diffs.append(f"fault {i} differs in {', '.join(bad)}")
            break
    # a killed session ("incomplete") replays to where it ends and is aborted there
    if original.outcome != replayed.outcome and (original.outcome, replayed.outcome) != ("incomplete", "aborted"):
        diffs.append(f"outcome {replayed.outcome!r}, the recording's was {original.outcome!r}")
    return Comparison(len(pr), len(fr), tuple(diffs))


# -- the command -----------------------------------------------------------------------------------

def run(args) -> int:
    from station.config import load_config
    from station.progress import ConsoleProgress
    from station.wiring import open_replay_rig

    source = Path(args.session)
    session = read_session(source)
    out = Path(args.out) if args.out else source.with_name(source.stem + ".replay.h5")
    if out.resolve() == source.resolve():
        raise InputError(f"--out {out} is the recording being replayed; choose another file")
    if out.exists():
        raise InputError(f"{out} exists; choose another --out (a replay never overwrites a session)")
    if not session.plan:
        raise InputError(f"{source}: the session stores no sweep plan, so there is nothing to replay")
    cfg = load_config(None)
    pace = "as fast as possible" if args.speed is None else ("real time" if args.speed == 1 else f"{args.speed:g}x real time")
    print(f"replaying {source} ({len(session.points)} points, outcome {session.outcome}) {pace}")
    with open_replay_rig(source, args.speed, cfg) as rig:
        result = replay_sweep(rig, session, out, cfg, sinks=[ConsoleProgress()])
        mismatch = rig.sim.mismatch
    print(f"session: {out} ({result.outcome}, {result.points} points; rig replay)")
    if mismatch is not None:
        raise mismatch
    cmp = compare_sessions(session, read_session(out))
    if cmp.identical:
        print(f"identical to the recording: {cmp.points} points (all fields), {cmp.faults} faults, outcome {result.outcome}")
        print(f"next: station fit {out} --out model.json   (gives the model of {source})")
        return 0
    print("differs from the recording:")
    for line in cmp.differences:
        print(f"  {line}")
    return 1

