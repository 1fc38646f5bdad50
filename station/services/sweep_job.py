"""The sweep job, new or resumed, for every front end (issue 32 part 1): `station sweep`, `station
run` and the terminal UI's Sweep page fill a `SweepRequest`; `prepare_sweep` makes every refusal,
output check and size estimate before anything connects, moves or is written; the JobRunner
(station/services/job.py) runs the `PreparedSweep`: its `check()` reads which legs apply a
compensation table (the question of a sweep of a compensated leg, check_compensation) holding the
rig lock, then `run` sweeps through the one runner (station.services.jobs.run_sweep).

Imports of the procedures are inside the functions: a request and its refusal load nothing heavy.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Iterable, Iterator, Mapping

from procedures.acquisition.plan_spec import DEFAULT_CYCLES, PLAN_KINDS  # noqa: F401 (what SweepRequest.kind and .cycles take)
from procedures.vocabulary import InputError
from station.services.config import StationConfig
from station.services.job import JobOutcome, require_legs

if TYPE_CHECKING:  # annotations only: a request and its refusal load nothing heavy
    import numpy as np

    from procedures.acquisition.plan_spec import PlanSpec
    from procedures.acquisition.plans import SweepPlan
    from procedures.engine.control import RunControl
    from procedures.engine.runner import Sink
    from station.services.wiring import Rig


class OutputExists(InputError):
    """A new session's file exists already (nothing was written): the front end says how to go
    on (the command line's --force / --resume, the UI's another file name)."""

    def __init__(self, path: Path) -> None:
        super().__init__(f"{path}: exists already; a session is never overwritten; nothing was written")
        self.path = path


@dataclass
class SweepRequest:
    """A sweep as a front end asks for it: plain values (what the command line's options and the
    Sweep page's fields hold).

    `out`: the session file (None with `default_out_prefix`: a new name under the recordings
    folder). `resume`: `out` is an unfinished session, finished with its own plan (the plan
    fields are not used). `force`: a new session replaces `out`. `legs`: leg numbers, or their
    text ("1-6", "1,3"). The plan: `kind` (procedures.acquisition.plan_spec.PLAN_KINDS), `cycles`
    (None: the kind's standard), `n_targets` / `step_mm` / `targets_file`, `min_mm` .. `max_mm`,
    `overrun_mm`, `dwell_s`, `averaging_s`; or `plan`, a plan built already (a script, a test).
    `serials`: leg -> identity fields entered for this session; `serials_file`: their CSV.
    `time_scale`, `seed`: the simulated rig's. `beyond_limits`: the user accepted a plan beyond
    the config's [limits] (the UI asks; else it is refused). `build_in_run`: the plan is built by the run
    (abortable: a huge plan takes seconds; the UI) rather than by prepare. `make_parents`: the
    folder of `out` is made when missing. `index`: the session goes to the station's catalog."""

    out: str | Path | None = None
    resume: bool = False
    force: bool = False
    legs: tuple[int, ...] | str = (1,)
    kind: str = "iso230"
    cycles: int | None = None
    n_targets: int | None = None
    step_mm: float | None = None
    targets_file: str | Path | None = None
    min_mm: float = -90.0
    max_mm: float = 90.0
    overrun_mm: float = 2.0
    dwell_s: float = 1.0
    averaging_s: float = 0.1
    plan: SweepPlan | None = None
    serials: Mapping[int, Mapping[str, str]] = field(default_factory=dict)
    serials_file: str | None = None
    time_scale: float | None = None
    seed: int | None = None
    default_out_prefix: str | None = None
    beyond_limits: bool = False
    build_in_run: bool = False
    make_parents: bool = False
    index: bool = True
    ways_out: Mapping[str, str] | None = None  # how the front end rolls back / confirms (a refusal names them)


def check_time_scale(time_scale: float | None) -> None:
    """The simulated rig's time scale: real seconds per simulated second, a finite number >= 0
    (or not given)."""
    if time_scale is not None and not (math.isfinite(time_scale) and time_scale >= 0):
        raise InputError(f"--time-scale must be a number >= 0 (real seconds per simulated second; 0 = no "
                         f"waiting), got {time_scale:g}")


def plan_spec_of(request: SweepRequest):
    """The procedures' PlanSpec of `request` (PlanError, an InputError, when no plan has it)."""
    from procedures.acquisition.plan_spec import PlanSpec
    from procedures.acquisition.plans import parse_legs

    legs = parse_legs(request.legs) if isinstance(request.legs, str) else tuple(int(x) for x in request.legs)
    return PlanSpec(legs=legs, kind=request.kind, cycles=request.cycles, n_targets=request.n_targets,
                    step_mm=request.step_mm, targets_file=Path(request.targets_file) if request.targets_file else None,
                    min_mm=request.min_mm, max_mm=request.max_mm, overrun_mm=request.overrun_mm,
                    dwell_s=request.dwell_s, averaging_s=request.averaging_s)


def build_plan_of(request: SweepRequest, limits=None):
    """The plan `request` asks for (a procedures SweepPlan); with `limits` (the config's [limits])
    sized first and refused beyond them before anything is built."""
    from procedures.acquisition.plan_spec import plan_from_spec

    return plan_from_spec(plan_spec_of(request), limits)


@dataclass(frozen=True)
class SweepSize:
    """What a sweep will take, as a front end shows it before it starts."""

    legs: tuple[int, ...]
    kind: str
    points: int
    rig_hours: float
    file_bytes: float
    text: str  # "N points, about H h on the rig, a file of about B" (PlanSize.describe)
    bytes_text: str  # the file size, e.g. "1.2 MB"
    over_limits: str  # "" when within the config's [limits]; else how it exceeds them (and what fits)


def estimate(request: SweepRequest, cfg: StationConfig | None = None) -> SweepSize:
    """The size of the sweep `request` asks for, without building it (InputError for a plan no
    sweep has). With `cfg`, `over_limits` says whether its [limits] take it."""
    from procedures.acquisition.plan_size import fmt_bytes, plan_size

    spec = plan_spec_of(request)
    size = plan_size(spec)
    over = ""
    if cfg is not None:
        try:
            cfg.limits.check(spec)
        except InputError as exc:
            over = str(exc)
    return SweepSize(spec.legs, spec.kind, size.points, size.rig_hours, size.file_bytes, size.describe(),
                     fmt_bytes(size.file_bytes), over)


@dataclass
class PreparedSweep:
    """A sweep that passed every check made without the devices (prepare_sweep). `plan` (None
    until the run builds it, with `build_in_run`), `out`, `total_points`, `lines` (what it will
    do), `recorded` (a resumed session's points already measured, a structured array)."""

    request: SweepRequest
    cfg: StationConfig
    out: Path
    legs: tuple[int, ...]
    kind: str
    total_points: int
    plan: SweepPlan | None = None
    spec: PlanSpec | None = None  # the PlanSpec built in the run (build_in_run)
    lines: list[str] = field(default_factory=list)
    recorded: np.ndarray | None = None
    rig: Rig | None = None  # bound by prepare_sweep(rig=) or connect()
    question: str | None = None
    declined: str = ""
    needs_rig: bool = True

    @contextlib.contextmanager
    def connect(self, sim_memory: bool = True) -> Iterator[Rig]:
        """Open the rig the config names for this sweep's legs and bind it while in the block.
        `sim_memory`: the simulated drives keep their tables where push/verify/rollback --sim and
        the UI find them (its folder made only now, when everything was accepted)."""
        from station.services.wiring import open_rig

        if sim_memory:
            self.cfg.with_sim_memory()
        with open_rig(self.cfg, legs=self.legs, time_scale=self.request.time_scale) as rig:
            self.rig = rig
            try:
                yield rig
            finally:
                self.rig = None

    def check(self) -> None:
        """The checks that read the devices, under the rig lock before anything moves: every leg
        has a drive; a leg applying a compensation table is asked about (`question`; a resumed
        session goes on only with the table state it started with: check_compensation)."""
        from station.services.jobs import active_tables_now, compensated_question, compensated_refusal, \
            resume_table_refusal

        require_legs(None if self.rig is None else self.rig.axes, self.legs)
        if self.kind == "verification":
            return
        now = active_tables_now(self.rig, self.legs)
        if self.request.resume:
            resume_table_refusal(self.out, self.legs, now)
            return
        if now:
            self.question = compensated_question(now)
            self.declined = compensated_refusal(now, self.request.ways_out)

    def run(self, sinks: Iterable[Sink] = (), control: RunControl | None = None) -> JobOutcome:
        """Sweep (after `check()` and the question, which the JobRunner makes): the plan built
        first when `build_in_run` (an abort meanwhile ends it: nothing moved or written)."""
        from station.services.jobs import run_sweep

        if self.plan is None:
            from procedures.acquisition.plan_size import build_abortable

            self.plan = build_abortable(self.spec, control)
            if self.plan is None:
                return JobOutcome("aborted", lines=["aborted before it began; nothing moved, nothing recorded"])
        if self.request.force and not self.request.resume and self.out.exists():
            self.out.unlink()  # --force: the new session replaces it (everything was accepted)
        result = run_sweep(self.rig, self.plan, self.out, self.cfg, sinks=sinks, control=control,
                           resume=self.request.resume, serials=self.request.serials,
                           serials_file=self.request.serials_file, index=self.request.index, tables_checked=True)
        return JobOutcome(result.outcome, outputs=[self.out] if self.out.exists() else [], run=result,
                          data=self.plan)


def prepare_sweep(request: SweepRequest, cfg: StationConfig, rig: Rig | None = None) -> PreparedSweep:
    """Every refusal of `request` made without moving or writing anything: the simulated rig's
    options, the serials, the session file (a new one not there unless `force`, its folder there;
    a resumed one writable, with something left to measure), the plan sized against the config's
    [limits] and built (unless `build_in_run`).
    `rig`: the connected rig, when the front end holds one (the UI). InputError otherwise."""
    from procedures.io.outputs import check_appendable, check_output_file
    from station.services.session_identity import leg_fields
    from station.services.serials import serials_unverified_line

    lines: list[str] = []
    check_time_scale(request.time_scale)
    if request.seed is not None:
        cfg.sim.seed = request.seed
    if request.resume and (request.serials or request.serials_file):
        raise InputError("--serial/--serials name the legs of a new session; a resumed session keeps the identity "
                         "it was created with: drop them")
    if not request.resume:
        leg_fields(cfg, request.serials, request.serials_file)  # a bad serials file is refused before anything moves
        unverified = serials_unverified_line(request.serials_file or cfg.serials_file)
        if unverified:  # a list typed by hand: read whole, but nothing proves it (procedures/io/integrity.py)
            lines.append(unverified)
    recorded = None
    spec = None
    if request.resume:
        if request.out is None:
            raise InputError("no session file to resume given")
        out = check_appendable(request.out)  # before the recording's modules load (h5py, the catalog)
        from procedures.io.recording.reader import read_session
        from station.services.jobs import resumable_plan

        plan = resumable_plan(out)
        recorded = read_session(out).points
        legs, kind, total = plan.legs, plan.kind, plan.total_points
    else:
        if request.out is None:
            if request.default_out_prefix is None:
                raise InputError("no session file given: where to record the session (--out FILE.h5)")
            from station.services.sessions import default_session_path

            request.out = default_session_path(cfg, prefix=request.default_out_prefix)
        out = Path(request.out)
        if out.exists() and not request.force and out.suffix.lower() == ".h5":
            raise OutputExists(out)
        out = check_output_file(out, force=request.force, suffixes=(".h5",), make_parents=request.make_parents)
        plan = request.plan
        if plan is not None:
            legs, kind, total = plan.legs, plan.kind, plan.total_points
        else:
            from procedures.acquisition.plan_size import check_plan_size, plan_size

            spec = plan_spec_of(request)
            limits = None if request.beyond_limits else cfg.limits
            # sized (and refused when huge) before anything is built
            size = plan_size(spec) if limits is None else check_plan_size(spec, limits)
            lines.append(f"plan: {size.describe()}")
            legs, kind, total = spec.legs, spec.kind, size.points
            if not request.build_in_run:
                from procedures.acquisition.plan_spec import plan_from_spec

                plan = plan_from_spec(spec, limits)
    if plan is not None:
        lines.extend(f"note: {note}" for note in plan.notes)
    job = PreparedSweep(request, cfg, out, tuple(legs), kind, total, plan=plan, spec=spec, lines=lines,
                        recorded=recorded, rig=rig)
    if rig is not None:
        missing = [leg for leg in job.legs if leg not in rig.axes]
        if missing:
            raise InputError(f"no drive connected for leg(s) {missing} (connected: {sorted(rig.axes)}); "
                             "nothing moved")
    return job


def iso230_lines(path: str | Path) -> list[str]:
    """The ISO 230-2 evaluation of the session `path` as `station run` prints it after its sweep:
    the error basis (normalised to 20 degC, as station iso230 and fit), the table, each value
    with its expanded uncertainty U (k = 2)."""
    from procedures.io.recording.reader import read_session
    from procedures.metrology.thermal import error_basis
    from procedures.reporting.iso230 import evaluate, format_table
    from station.services.report_jobs import iso_lines, session_iso230

    session = read_session(path)
    points, basis_lines, _ = error_basis(session, False)
    return [*basis_lines, format_table(evaluate(points)), *iso_lines(session_iso230(session))]
