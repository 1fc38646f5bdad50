"""The recording sink: writes a sweep's events into an HDF5 session file.

It is the runner's *critical* sink: if it cannot write, the run stops. A point is durable (in
the session's journal, writer.py) before `handle` returns, i.e. before the procedure makes the
next move; a procedure's SweepFinished writes the last batch to the HDF5 file and closes it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from procedures.engine import events as ev
from procedures.io.recording.writer import SessionWriter
from procedures.vocabulary import Outcome


class RecorderSink:
    critical = True

    def __init__(self, path: str | Path, *, operator: str = "", rig: str = "sim",
                 station_config: dict[str, Any] | None = None, software_version: str = "",
                 resume: bool = False, identity: dict[str, Any] | None = None) -> None:
        self.path = Path(path)
        self.operator = operator
        self.rig = rig
        self.station_config = station_config or {}
        self.software_version = software_version
        self.resume = resume
        self.identity = identity  # SessionIdentity.to_json() (procedures/io/recording/identity.py)
        self.writer: SessionWriter | None = None

    def handle(self, event: ev.Event) -> None:
        if isinstance(event, ev.SweepStarted):
            if self.resume:
                self.writer = SessionWriter.resume(self.path)
            else:
                self.writer = SessionWriter.create(
                    self.path, session_id=event.session_id, operator=self.operator, rig=self.rig,
                    plan=event.plan, station_config=self.station_config, devices=event.devices,
                    software_version=self.software_version, identity=self.identity,
                )
        elif isinstance(event, ev.PointMeasured):
            assert self.writer is not None, "PointMeasured before SweepStarted"
            self.writer.append_point(event.record)
        elif isinstance(event, ev.Fault):
            if self.writer is not None:
                self.writer.append_fault({
                    "index": event.index, "leg": event.leg, "run": event.run, "target_mm": event.target_mm,
                    "time_s": event.t_s, "kind": str(event.kind), "attempt": event.attempt,
                    "gave_up": int(event.gave_up), "message": event.message.encode("utf-8", "replace")[:200],
                })
        elif isinstance(event, ev.SweepFinished):
            # finished here, not only at close: a procedure that goes on after its sweep (a
            # verification) names the complete file, with its outcome, by its content hash
            self.close(event.outcome)

    def close(self, outcome: Outcome) -> None:
        if self.writer is not None:
            writer, self.writer = self.writer, None
            try:
                writer.finish(outcome)
            except BaseException:
                writer.close()  # never leave the file open and its lock behind (outcome unset)
                raise
