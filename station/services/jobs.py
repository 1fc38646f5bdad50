"""Jobs both front ends start: a sweep (new or resumed) through the one runner, and the replay of
a recorded session through the replay devices (`station replay`, the terminal UI's F5 page)."""

from __future__ import annotations

import math
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Mapping
from typing import Callable

from procedures.engine import events as ev
from procedures.engine.control import RunControl
from procedures.vocabulary import InputError
from procedures.io.numbers import NotANumber, finite_float
import numpy as np

from procedures.metrology.thermal import recorded_materials
from procedures.acquisition.plans import SweepPlan
from procedures.io.recording.reader import Session, read_session
from procedures.io.recording.schema import FLAG_FRAMES_LOST, FLAG_REPLAYED, FLAG_REREFERENCED
from procedures.io.recording.sink import RecorderSink
from procedures.engine.runner import RunResult, Sink, run
from procedures.acquisition.sweep import RetryPolicy, sweep
from station import __version__
from station.catalog.writer import CatalogSink
from station.services.config import StationConfig
from station.services.session_identity import session_identity
from station.services.wiring import Rig


class CompensatedSweepRefused(InputError):
    """A calibration sweep of a leg whose compensation table is active, not confirmed (nothing moved)."""


def active_tables_now(rig: Rig, legs: Iterable[int]) -> dict[int, str]:
    """leg -> the compensation table it applies now (procedures.acquisition.sweep.table_state),
    for the legs of `legs` that have one active; a leg whose state cannot be read is left out
    (the session then records "unknown (...)")."""
    from procedures.acquisition.sweep import table_state

    out = {}
    for leg in legs:
        if leg in rig.axes:
            state = table_state(rig.axes[leg])
            if state.active:
                out[int(leg)] = state.text
    return out


def compensated_question(tables: Mapping[int, str]) -> str:
    """The question both front ends ask before sweeping legs with an active table (the CLI at the
    terminal or by --yes, the UI in a dialog)."""
    which = "; ".join(f"leg {leg}: {text}" for leg, text in sorted(tables.items()))
    return (f"A compensation table is active ({which}). A calibration measures the leg as found, with no table: "
            "roll the table back first (station rollback, or the Compensation page). Sweep the compensated leg "
            "anyway? The session records the active tables and is stage 'other', not an as-found calibration.")


def compensated_refusal(tables: Mapping[int, str], how: Mapping[str, str] | None = None) -> str:
    """The refusal of a sweep of legs with an active table, not confirmed. `how`: how this front
    end does each way out ("rollback", "confirm"), added in parentheses (e.g. the command line's
    commands, the UI's keys); none: the sentence alone."""
    how = how or {}
    legs = ", ".join(str(leg) for leg in sorted(tables))
    rollback = f" ({how['rollback']})" if how.get("rollback") else ""
    confirm = f" ({how['confirm']})" if how.get("confirm") else ""
    return (f"leg(s) {legs}: a compensation table is active ({'; '.join(tables[k] for k in sorted(tables))}); "
            f"a calibration measures the leg as found: roll the table back first{rollback}, or confirm the sweep of "
            f"the compensated leg{confirm}, recorded as stage 'other'; nothing moved")


def check_compensation(rig: Rig, plan: SweepPlan, out: Path, resume: bool,
                       confirm: Callable[[str], bool] | None) -> None:
    """The one decision on a sweep of a compensated leg, for every front end (docs/compensation.md):
    a new session on legs with an active table starts only when `confirm(question)` says yes
    (the session then records the tables in its devices and is stage "other",
    procedures/io/recording/stage.py); `confirm` None = nobody to ask: refused. A resumed session
    goes on only with the tables it was started with (active or not on each leg): its points
    would otherwise mix two states of the leg. CompensatedSweepRefused (nothing moved)."""
    if plan.kind == "verification":  # the as-left sweep measures the compensated leg by design
        return
    now = active_tables_now(rig, plan.legs)
    if resume:
        resume_table_refusal(out, plan.legs, now)
        return
    if not now:
        return
    if confirm is None or not confirm(compensated_question(now)):
        raise CompensatedSweepRefused(compensated_refusal(now))


def resume_table_refusal(out: Path, legs: Iterable[int], now: Mapping[int, str]) -> None:
    """CompensatedSweepRefused when the session `out` was started with another table state on a
    leg of `legs` than `now` (leg -> its active table): its points would mix two states of the leg."""
    from procedures.io.recording.stage import active_tables

    recorded = active_tables(read_session(out).devices)
    changed = sorted(leg for leg in legs if (leg in now) != (leg in recorded))
    if changed:
        states = "; ".join(f"leg {leg}: {'table active now' if leg in now else 'no table active now'}, "
                           f"{'one' if leg in recorded else 'none'} when the session started" for leg in changed)
        raise CompensatedSweepRefused(f"{out}: cannot be resumed: {states}; its points would mix two states "
                                      "of the leg: restore the table state it was started with, or sweep a new "
                                      "session; nothing moved")


def run_sweep(
    rig: Rig,
    plan: SweepPlan,
    out: str | Path,
    cfg: StationConfig,
    sinks: Iterable[Sink] = (),
    control: RunControl | None = None,
    resume: bool = False,
    retry: RetryPolicy = RetryPolicy(),
    serials: Mapping[int, Mapping[str, str]] | None = None,
    serials_file: str | None = None,
    index: bool = True,
    confirm_compensated: Callable[[str], bool] | None = None,
    tables_checked: bool = False,
) -> RunResult:
    """Run `plan` on `rig`, recording to `out` (or appending to it when `resume`), and index the
    session in the station's catalog (`index` False: not, e.g. the sample sessions, which are
    made under temporary names and describe no real leg).

    `serials`: leg -> identity fields entered for this session (--serial, the Sweep page), on
    top of `serials_file` / [station] serials_file and [legs.N] (station/services/serials.py). The session
    records the identity (station/services/session_identity.py); the laser's calibration warnings are said at the
    start of every session, a resumed one too.

    `confirm_compensated(question) -> bool`: asked before a leg whose compensation table is
    active is swept (check_compensation; None: such a sweep is refused, CompensatedSweepRefused);
    `tables_checked`: the job has made that check already (PreparedSweep.check, under the rig lock)."""
    control = control or RunControl()
    out = Path(out)
    if not tables_checked:
        check_compensation(rig, plan, out, resume, confirm_compensated)  # before anything is written or moves
    done: frozenset[int] = frozenset()
    session_id = uuid.uuid4().hex[:12]
    if resume:
        session = read_session(out)
        done = frozenset(int(i) for i in session.points["index"])
        session_id = str(session.attrs.get("session_id", session_id))
    else:
        out.parent.mkdir(parents=True, exist_ok=True)
    identity = session_identity(cfg, plan.legs, rig.axes, __version__, serials, serials_file)
    recorder = RecorderSink(out, operator=cfg.operator, rig=rig.kind, station_config=cfg.to_dict(),
                            software_version=__version__, resume=resume, identity=identity.to_json())
    # the legs' own materials for the adaptive rule (the same the session records as
    # station_config.leg_materials and `station fit` normalises with)
    materials = {leg: cfg.material_of(leg) for leg in plan.legs}
    procedure = sweep(plan, rig.axes, rig.laser, rig.clock, control=control, done_indices=done,
                      retry=retry, session_id=session_id, materials=materials, warnings=identity.warnings)
    # the catalog sink after the recorder: it indexes the session once the recorder closed it
    catalog = [CatalogSink.deferred(cfg, out)] if index else []
    return run(procedure, [recorder, *catalog, *sinks], control)


def plan_of_recording(path: str | Path) -> SweepPlan:
    """The plan stored in a session file (for resume and replay)."""
    return SweepPlan.from_dict(read_session(path).plan)


def resumable_plan(path: str | Path) -> SweepPlan:
    """The plan of the session file `path`, if there is anything left to measure in it (what
    `run_sweep(..., resume=True)` then finishes: `station sweep --resume`, the UI's Sweep page).
    InputError naming the file when it holds no sweep plan (an imported file) or is complete."""
    session = read_session(path)
    if not session.plan or session.plan.get("kind") == "import":
        source = f"imported from {session.plan['source']}" if (session.plan or {}).get("source") else "imported from a CSV?"
        raise InputError(f"{path}: holds no sweep plan ({source}), so it cannot be resumed; sweep into a new session file instead")
    try:
        plan = plan_of_recording(path)
    except (ValueError, KeyError, TypeError) as exc:
        raise InputError(f"{path}: its sweep plan cannot be read back ({exc!r}); sweep into a new session file instead") from None
    done = len({int(i) for i in session.points["index"]})
    if done >= plan.total_points:
        raise InputError(f"{path}: already complete ({done} of {plan.total_points} points, outcome {session.outcome}); "
                         "nothing to resume")
    return plan


# -- replay of a recorded session ------------------------------------------------------------------

_KIND_LIMIT = {"beam_break": "beam_retries", "drive_fault": "drive_retries"}  # other kinds: comm_retries


def parse_speed(text: str) -> float | None:
    """'max' -> None (as fast as possible); '1' -> real time; '10' -> ten times faster.
    InputError saying what to type otherwise."""
    from station.values import REPLAY_SPEED  # the one parser of a speed factor, as `station replay --speed`

    return REPLAY_SPEED.parse(text)


def retry_policy_of(session: Session, base: RetryPolicy = RetryPolicy()) -> RetryPolicy:
    """The retry limits the recorded run must have had: a fault that gave up at attempt n means
    a limit of n - 1 for its kind; a fault that did not give up at attempt n means at least n.
    The environment is read at every point, so each replayed point gets the environment recorded
    with it, whatever the recorded run's reading interval was (`env_interval_s` is -inf rather than
    0 because the recorded clock restarts in a resumed session, and the sweep compares `now -
    last reading` with it), except at a point whose recorded environment (air, pressure,
    humidity, its leg's material temperature) is bit for bit the one of the point recorded just
    before it, of the same leg (`env_unchanged_at`): the values held are already the ones the
    recording holds, and a reading less is a pty round trip less per point (bench/bench_replay.py)."""
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
                       comm_retries=limits["comm_retries"], beam_wait_s=base.beam_wait_s, env_interval_s=-math.inf,
                       env_unchanged_at=env_unchanged_at(session.points))


_ENV_FIELDS = ("air_temp_c", "air_pressure_hpa", "humidity_pct", "material_temp_c")


def env_unchanged_at(points: np.ndarray) -> frozenset[int]:
    """Indices of recorded points whose environment is bit for bit that of the point with the
    index just before, of the same leg (retry_policy_of)."""
    if len(points) < 2 or not all(f in (points.dtype.names or ()) for f in _ENV_FIELDS):
        return frozenset()
    pts = np.sort(points, order="index")
    # bitwise: NaN equals NaN, -0.0 differs from 0.0
    same = np.ones(len(pts) - 1, dtype=bool)
    for f in _ENV_FIELDS:
        bits = np.ascontiguousarray(pts[f], dtype=np.float64).view(np.int64)
        same &= bits[1:] == bits[:-1]
    same &= (pts["leg"][1:] == pts["leg"][:-1]) & (pts["index"][1:] == pts["index"][:-1] + 1)
    return frozenset(int(i) for i in pts["index"][1:][same])


STREAM_FLAGS = FLAG_FRAMES_LOST | FLAG_REREFERENCED
"""What a streaming laser (the µLine-F1) said of a reading that the replay instrument, speaking
the station's line protocol, cannot say again: taken from the recorded point (docs/replay.md)."""


class ReplayRecorderSink(RecorderSink):
    """The recorder sink, with FLAG_REPLAYED set on every point it writes, and the recorded
    point's STREAM_FLAGS (`stream_flags`: plan index -> those bits of the recording); at the
    points in `unknown_signal` (a streamed on-the-fly pass: no signal level at a target, which
    the station's protocol cannot carry: drivers.replay.script.UNKNOWN_SIGNAL_PCT) the recorded NaN."""

    def __init__(self, *args, stream_flags: dict[int, int] | None = None, unknown_signal: frozenset[int] = frozenset(),
                 **kwargs):
        super().__init__(*args, **kwargs)
        self.stream_flags = stream_flags or {}
        self.unknown_signal = unknown_signal

    def handle(self, event: ev.Event) -> None:
        if isinstance(event, ev.PointMeasured):
            record = dict(event.record)
            index = int(record["index"])
            record["flags"] = (int(record.get("flags", 0)) | FLAG_REPLAYED | self.stream_flags.get(index, 0))
            if index in self.unknown_signal:
                record["signal_pct"] = float("nan")
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
    """Run `session`'s plan on the replay `rig` (station.services.wiring.open_replay_rig) through the
    sweep procedure and the runner, recording to `out` (rig kind "replay").

    Where the recording was cut short (aborted, killed), the run is aborted where the recording
    ends; a recorded give-up ends it "failed" at the same point. If a device met a request the
    recording does not hold, `rig.sim.mismatch` names the first one (the run then fails).
    """
    if rig.kind != "replay":
        raise InputError(f"replay_sweep needs a replay rig (station.services.wiring.open_replay_rig), not a {rig.kind} rig")
    cfg = cfg or StationConfig()
    control = control or RunControl()
    plan = SweepPlan.from_dict(session.plan)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rig.sim.on_end = lambda reason: control.abort(reason)
    control.on_abort(rig.clock.cancel_waits)
    # the replayed legs are the recorded ones: the new file names them as the recording did
    recorder = ReplayRecorderSink(out, operator=cfg.operator, rig="replay", station_config=cfg.to_dict(),
                                  software_version=__version__,
                                  identity=session.identity.to_json() if session.identity.recorded else None,
                                  stream_flags={int(i): int(f) & STREAM_FLAGS for i, f in
                                                zip(session.points["index"], session.points["flags"]) if int(f) & STREAM_FLAGS},
                                  unknown_signal=frozenset(int(i) for i in
                                                           session.points["index"][np.isnan(session.points["signal_pct"])]))
    # t0_s=0: recorded times are seconds since the session start, so `now - 0` is bit-exact
    # the materials the recorded run's adaptive rule used (its station_config.leg_materials), so
    # it stops where the recording did; a session that recorded none: this config's
    recorded = recorded_materials(session.station_config)
    materials = recorded[1] if recorded else {leg: cfg.material_of(leg) for leg in plan.legs}
    procedure = sweep(plan, rig.axes, rig.laser, rig.clock, control=control, retry=retry_policy_of(session),
                      session_id=uuid.uuid4().hex[:12], t0_s=0.0, materials=materials)
    return run(procedure, [recorder, *sinks], control)


@dataclass(frozen=True)
class ReplayOutcome:
    """How a replay ended: the run's result, the first request the recording did not hold
    (`mismatch`, the run then failed), and the comparison of the new recording with the replayed
    one (None after a mismatch or an abort: nothing worth comparing)."""

    result: RunResult
    mismatch: Exception | None
    comparison: object | None  # procedures.acquisition.replay_compare.Comparison


def replay_and_compare(source: Path, session: Session, out: Path, cfg: StationConfig, speed: float | None,
                       sinks: Iterable[Sink] = (), control: RunControl | None = None,
                       on_rig_opened: Callable[[Rig], None] | None = None) -> ReplayOutcome:
    """Replay the recording `source` (read as `session`) through the replay devices at `speed`
    (None: as fast as possible), recording to `out`, and compare the two recordings: the job of
    `station replay` and of the terminal UI's Replay page. `on_rig_opened(rig)` is told the
    replay rig once it runs (the UI keeps it)."""
    from procedures.acquisition.replay_compare import compare_sessions
    from station.services.wiring import open_replay_rig

    with open_replay_rig(source, speed, cfg) as rig:
        if on_rig_opened is not None:
            on_rig_opened(rig)
        result = replay_sweep(rig, session, out, cfg, sinks=sinks, control=control)
        mismatch = rig.sim.mismatch
    comparison = None
    if mismatch is None and not (control is not None and control.aborted):
        comparison = compare_sessions(session, read_session(out))
    return ReplayOutcome(result, mismatch, comparison)
