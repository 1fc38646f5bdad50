"""Jobs both front ends start: a sweep (new or resumed) through the one runner."""

from __future__ import annotations

import uuid
from pathlib import Path
from typing import Iterable

from procedures.control import RunControl
from procedures.plans import SweepPlan
from procedures.recording.reader import read_session
from procedures.recording.sink import RecorderSink
from procedures.runner import RunResult, Sink, run
from procedures.sweep import RetryPolicy, sweep
from station import __version__
from station.config import StationConfig
from station.wiring import Rig


def run_sweep(
    rig: Rig,
    plan: SweepPlan,
    out: str | Path,
    cfg: StationConfig,
    sinks: Iterable[Sink] = (),
    control: RunControl | None = None,
    resume: bool = False,
    retry: RetryPolicy = RetryPolicy(),
) -> RunResult:
    """Run `plan` on `rig`, recording to `out` (or appending to it when `resume`)."""
    control = control or RunControl()
    out = Path(out)
    done: frozenset[int] = frozenset()
    session_id = uuid.uuid4().hex[:12]
    if resume:
        session = read_session(out)
        done = frozenset(int(i) for i in session.points["index"])
        session_id = str(session.attrs.get("session_id", session_id))
    else:
        out.parent.mkdir(parents=True, exist_ok=True)
    recorder = RecorderSink(out, operator=cfg.operator, rig=rig.kind, station_config=cfg.to_dict(),
                            software_version=__version__, resume=resume)
    procedure = sweep(plan, rig.axes, rig.laser, rig.clock, control=control, done_indices=done,
                      retry=retry, session_id=session_id)
    return run(procedure, [recorder, *sinks], control)


def plan_of_recording(path: str | Path) -> SweepPlan:
    """The plan stored in a session file (for resume and replay)."""
    return SweepPlan.from_dict(read_session(path).plan)
