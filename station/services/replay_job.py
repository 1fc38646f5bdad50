"""The replay job (issue 32 part 1, one shape for every job): `station replay` fills a
`ReplayRequest`; `prepare_replay` reads the recording and makes every refusal (the output is the
recording itself or exists, no plan to replay); `PreparedReplay.run(sinks, control)` replays it
through the replay devices and compares the new recording with the original
(station.services.jobs.replay_and_compare)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from procedures.vocabulary import InputError
from station.services.job import JobOutcome, config_or_load

if TYPE_CHECKING:  # annotations only: a request and its refusal load nothing heavy
    from procedures.io.recording.reader import Session
    from station.services.config import StationConfig


@dataclass
class ReplayRequest:
    """Replay the recording `session` into `out` (None: NAME.replay.h5 beside it; replaced only
    with `force`) at `speed` (1 = real time, N = N times faster, None = as fast as possible);
    `make_parents`: create the folders of `out` (the UI's recordings folder) rather than refuse."""

    session: Path
    out: Path | None = None
    speed: float | None = None
    force: bool = False
    make_parents: bool = False


def pace_text(speed: float | None) -> str:
    return "as fast as possible" if speed is None else ("real time" if speed == 1 else f"{speed:g}x real time")


@dataclass
class PreparedReplay:
    """A replay that passed every check. `lines`: what it will do (print before run)."""

    source: Path
    session: Session
    out: Path
    speed: float | None
    replace: bool
    cfg: StationConfig
    needs_rig: bool = False  # the replay devices answer from the file: no drive moves
    question: str | None = None
    lines: list[str] = field(default_factory=list)
    on_rig_opened: Callable[[Any], None] | None = None  # told the replay rig once it runs (the UI keeps it)

    def run(self, sinks=(), control=None) -> JobOutcome:
        """The outcome's status is the run's; `data` the ReplayOutcome (its `mismatch`: the first
        request the recording did not hold; `comparison`: field by field)."""
        from station.services.jobs import replay_and_compare

        if self.replace and self.out.exists():
            self.out.unlink()  # --force: the new replay session replaces it
        ended = replay_and_compare(self.source, self.session, self.out, self.cfg, self.speed, sinks=sinks,
                                   control=control, on_rig_opened=self.on_rig_opened)
        result = ended.result
        lines = [f"session: {self.out} ({result.outcome}, {result.points} points; rig replay)"]
        cmp = ended.comparison
        if ended.mismatch is None and cmp is not None:
            if cmp.identical:
                lines += [f"identical to the recording: {cmp.points} points (all fields), {cmp.faults} faults, "
                          f"outcome {result.outcome}",
                          f"next: station fit {self.out} --out model.json   (gives the model of {self.source})"]
            else:
                lines += ["differs from the recording:"] + [f"  {line}" for line in cmp.differences]
        return JobOutcome(str(getattr(result.outcome, "value", result.outcome)), outputs=[self.out], lines=lines,
                          data=ended)


def prepare_replay(request: ReplayRequest, cfg: StationConfig | None = None) -> PreparedReplay:
    """Read the recording and refuse what cannot be replayed (InputError, nothing written)."""
    from procedures.io.outputs import check_output_file
    from procedures.io.recording.reader import read_session

    source = Path(request.session)
    session = read_session(source)
    out = Path(request.out) if request.out else source.with_name(source.stem + ".replay.h5")
    if out.resolve() == source.resolve():
        raise InputError(f"--out {out} is the recording being replayed; choose another file")
    check_output_file(out, force=request.force, suffixes=(".h5",), make_parents=request.make_parents)
    if not session.plan:
        raise InputError(f"{source}: the session stores no sweep plan, so there is nothing to replay")
    refusal = onthefly_refusal(session, source)
    if refusal:
        raise InputError(refusal)
    cfg = config_or_load(cfg)
    lines = [f"replaying {source} ({len(session.points)} points, outcome {session.outcome}) {pace_text(request.speed)}"]
    if (session.station_config.get("interferometer") or {}).get("protocol") == "linef1":
        # say how, so nobody takes the replay for a test of the µLine-F1's frames (docs/replay.md)
        lines.append("recorded with the µLine-F1: its recorded readings are served by the replay instrument over the "
                     "station's protocol" + (", each pass's at the replay drive's compare pulses"
                                             if (session.plan or {}).get("speeds_mm_s") else ""))
    return PreparedReplay(source, session, out, request.speed, request.force, cfg, lines=lines)


def onthefly_refusal(session: Session, source: Path) -> str | None:
    """Why an on-the-fly session cannot be replayed faithfully, in one line (None: it can).

    A pass is replayed by latching the recorded reading of each target at the replay drive's
    compare pulse (docs/replay.md), with either laser: the recording holds each pass's readings
    (for a streaming laser, the µLine-F1, the result of aligning its samples with the drive's
    trace), not the samples nor the trace. A pass retried after a fault of the laser (a beam break,
    an error, a time-out, line noise: e.g. a gap in the µLine-F1's stream) is replayed failing the
    same way at the recorded time (drivers.replay.plant.ONTHEFLY_FAULTS); one retried after a
    drive fault inside the moving pass cannot be made to fail the same way (a replay drive faults
    on arriving at a recorded point), so such a session is refused here rather than replayed into
    a mismatch halfway, or into another run."""
    from drivers.replay.plant import ONTHEFLY_FAULTS
    from procedures.acquisition.plans import SweepPlan

    try:
        plan = SweepPlan.from_dict(session.plan)
    except (ValueError, TypeError, KeyError):
        return None  # the replay rig says what is wrong with the plan (station.services.wiring)
    if not plan.onthefly:
        return None
    for f in session.faults:
        run, kind = int(f["run"]), _text(f["kind"])
        if plan.is_probe_run(run) or kind in ONTHEFLY_FAULTS:
            continue  # a reversal probe is a stop-and-go reading: its faults replay as a point's
        what = kind.replace("_", " ") + ("" if "fault" in kind else " fault")
        return (f"{source}: leg {int(f['leg'])} on-the-fly pass {run} met a {what} (attempt {int(f['attempt'])}) and "
                f"was {'given up' if int(f['gave_up']) else 'retried'}; a replay cannot make a moving pass fail with a "
                f"{what} again (only with the laser's faults), so it is refused; analyse the recording itself "
                f"(station fit {source} --out model.json)")
    return None


# -- a recording as the Replay page shows it --------------------------------------------------------

@dataclass
class Recording:
    """A recording read for a page: the session (procedures.io.recording.reader.Session) and what
    it holds in words and rows."""

    path: Path
    session: Session

    def summary(self) -> dict[str, Any]:
        """outcome, points, legs, faults (count), plan kind, targets (mm), cycles, rig, operator,
        schema, started and ended (UTC), as recorded ('?' where the file does not say)."""
        s = self.session
        plan = s.plan or {}
        return {"outcome": s.outcome, "points": len(s.points), "legs": s.legs, "faults": len(s.faults),
                "kind": plan.get("kind", "?"), "targets_mm": list(plan.get("targets_mm") or []),
                "cycles": plan.get("cycles", "?"), "rig": s.attrs.get("rig", "?"),
                "operator": s.attrs.get("operator", "?"), "schema": s.schema_version,
                "started_utc": s.attrs.get("started_utc", "?"), "ended_utc": s.attrs.get("ended_utc", "?")}

    def fault_rows(self, label: str) -> list[tuple[str, ...]]:
        """One row per fault record (procedures.io.recording.schema.FAULT_DTYPE, file order): `label`,
        index (the plan point), leg, run, target mm, time s, kind, attempt, gave up, message."""
        return [(label, str(int(f["index"])), str(int(f["leg"])), str(int(f["run"])), f"{float(f['target_mm']):+.4f}",
                 f"{float(f['time_s']):.3f}", _text(f["kind"]), str(int(f["attempt"])),
                 "yes" if int(f["gave_up"]) else "no", _text(f["message"]))
                for f in self.session.faults]


def _text(value) -> str:
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value)


def read_recording(path: str | Path) -> Recording:
    """Read the recording at `path` (a damaged file is refused by the reader within seconds)."""
    from procedures.io.recording.reader import read_session

    return Recording(Path(path), read_session(path))
