"""Push and rollback as jobs of the one shape (issue 32 part 1), for every front end: `station
push` / `station rollback` and the Compensation page fill a `PushRequest` / `RollbackRequest`;
`prepare_push` / `prepare_rollback` make every refusal that needs no drive (a bad leg, a table
file that cannot be read, a leg whose table the controller applies, values that look like a unit
slip) and return either a `PreparedRefusal` (its run writes the refusal's audit line, nothing
reaches a drive) or a prepared operation the JobRunner runs holding the rig: the procedures of
procedures.compensation.push through station.services.table_jobs (audit sink, catalog).

How the user confirms the plan the procedure shows is the front end's (`confirm_plans`: a
terminal prompt, a dialog); what it shows of a plan is `plan_lines` (the plan's own lines, with
or without the volatile drive address and the checksums), never lines cut up.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable, Iterator, Mapping

from procedures.vocabulary import InputError
from station.services.config import StationConfig
from station.services.job import JobOutcome, OfflineJob, require_legs

if TYPE_CHECKING:  # annotations only: a request and its refusal load nothing of the procedures
    from drivers.interfaces import ServoAxis
    from procedures.compensation.audit import AuditLog
    from procedures.compensation.push import PushPlan
    from procedures.compensation.table import LegTable
    from procedures.engine.control import RunControl
    from procedures.engine.runner import Sink
    from procedures.metrology.plausibility import Override
    from station.services.wiring import DriveHandle

PUSH, ROLLBACK = "push", "rollback"  # the audit log's actions (its entries' `action`)


@dataclass
class PushRequest:
    """A push as a front end asks for it: `legs` (a number, "1-6", "1,4", "all", or numbers),
    the table CSV `table` (the command line) or the `tables` made on the page (leg -> LegTable,
    with their `sources`), the name the refusals give it (`table_name`), `accept_implausible`
    (push corrections beyond 100 um; `accept_how` / `accepted_as`: how this front end lets the
    user accept them, None: the command line's --accept-implausible), the audit log (`audit`,
    None: the station's)."""

    legs: tuple[int, ...] | str | int
    table: str | Path | None = None
    tables: Mapping[int, LegTable] | None = None
    sources: Mapping[int, dict] | None = None
    table_name: str | None = None
    accept_implausible: bool = False
    accept_how: str | None = None
    accepted_as: str | None = None
    audit: str | Path | None = None


@dataclass
class RollbackRequest:
    """A rollback of `leg` as a front end asks for it (the audit log `audit`, None: the station's)."""

    leg: int
    audit: str | Path | None = None


def accept_override(how: str | None, kept: str | None = None) -> Override:
    """How a front end lets its user accept implausible values (procedures.metrology.plausibility.Override):
    `how` the refusal says to do it, `kept` what kept them; None: the command line's option."""
    from procedures.metrology.plausibility import Override

    return Override() if how is None else Override(how=how, kept=kept or how)


@dataclass
class PreparedRefusal(OfflineJob):
    """A push, rollback or verify refused before any drive was reached: `run` logs it in the
    audit log (as every refusal) and returns the refused outcome. `implausible`: refused for
    values that look like a unit slip (the user may accept them)."""

    action: str
    leg: int
    reason: BaseException | str
    cfg: StationConfig
    audit: AuditLog
    source: dict | None = None
    implausible: bool = False

    def run(self, sinks: Iterable[Sink] = (), control: RunControl | None = None) -> JobOutcome:
        from station.catalog.writer import catalog_for
        from station.services.table_jobs import refusal_job
        from station.services.wiring import drive_url_of

        job = refusal_job(self.action, self.leg, self.reason, audit=self.audit, drive_url=drive_url_of(self.cfg),
                          source=self.source, sinks=sinks, catalog=catalog_for(self.cfg))
        job.implausible = self.implausible
        return job


@dataclass
class PreparedTableOperation:
    """A push or rollback that passed every check made without the drives. The drives: bound by
    `connect()` (the command line opens them) or `axes` (the UI's connected rig). `confirm_plans`:
    how the user confirms (one PushPlan, or a list of them for several legs); until a front end
    sets it, nobody is asked and the operation is cancelled (nothing written)."""

    action: str
    request: PushRequest | RollbackRequest
    cfg: StationConfig
    legs: tuple[int, ...]
    audit: AuditLog
    tables: dict[int, LegTable] = field(default_factory=dict)
    sources: dict[int, dict] = field(default_factory=dict)
    warned: list[str] = field(default_factory=list)
    lines: list[str] = field(default_factory=list)
    axes: dict[int, ServoAxis] | None = None
    drive_url: str = ""
    confirm_plans: Callable[[PushPlan | list[PushPlan]], bool] = field(default=lambda plans: False)
    needs_rig: bool = True
    question: str | None = None

    @contextlib.contextmanager
    def connect(self) -> Iterator[DriveHandle]:
        """Open the drives of the legs alone (never the interferometer) and bind them in the block."""
        from station.services.wiring import open_drive

        with open_drive(self.cfg, self.legs) as drive:
            self.axes, self.drive_url = dict(drive.axes), drive.url
            try:
                yield drive
            finally:
                self.axes = None

    def check(self) -> None:
        require_legs(self.axes, self.legs, "the drives", "nothing was written")

    def run(self, sinks: Iterable[Sink] = (), control: RunControl | None = None) -> JobOutcome:
        from station.catalog.writer import catalog_for
        from station.services.session_identity import configured_serials
        from station.services.table_jobs import push_job, push_legs_job, rollback_job

        catalog = catalog_for(self.cfg)
        if self.action == ROLLBACK:
            leg = self.legs[0]
            return rollback_job(self.axes[leg], audit=self.audit, drive_url=self.drive_url,
                                confirm=self.confirm_plans, sinks=sinks, catalog=catalog)
        request = self.request
        serials = configured_serials(self.cfg)
        override = accept_override(request.accept_how, request.accepted_as)
        name = request.table_name or (str(request.table) if request.table else None)
        if len(self.legs) == 1:
            leg = self.legs[0]
            job = push_job(self.axes[leg], self.tables[leg], audit=self.audit, drive_url=self.drive_url,
                           source=self.sources.get(leg), confirm=self.confirm_plans, leg_serial=serials.get(leg),
                           sinks=sinks, catalog=catalog, accept_implausible=request.accept_implausible,
                           table_name=name, override=override)
        else:
            job = push_legs_job({leg: self.axes[leg] for leg in self.legs}, self.tables, audit=self.audit,
                                drive_url=self.drive_url, sources=self.sources, confirm=self.confirm_plans,
                                leg_serials=serials, sinks=sinks, catalog=catalog,
                                accept_implausible=request.accept_implausible, table_name=name, override=override)
        return job


def parse_legs_text(text: tuple[int, ...] | str | int) -> tuple[int, ...]:
    """Leg numbers of a request: a number, numbers, or text "3", "1-6", "1,4", "all"."""
    from station.services.verify_job import parse_leg_choice

    if isinstance(text, int):
        return (text,)
    return parse_leg_choice(text)


def _configured_limit_um(cfg: StationConfig, leg: int) -> float:
    """What leg `leg`'s table holder takes by the config, without connecting (inf when unknown)."""
    from station.services.wiring import leg_table_spec

    try:
        return leg_table_spec(cfg, leg).max_correction_um
    except InputError:
        return float("inf")


def drive_text(cfg: StationConfig) -> str:
    """Which drive a push or rollback writes to, said before anything else."""
    if cfg.drive.url == "sim":
        return f"the SIMULATED drive (its table memory {cfg.sim.nv_path}); not a real drive"
    return f"{cfg.drive.url}" + (f" (config {cfg.source})" if cfg.from_file else "")


def _target_lines(cfg: StationConfig, legs: Iterable[int]) -> list[str]:
    from station.services.table_jobs import target_text

    return [f"compensation target of leg {leg}: {target_text(cfg, leg)}" for leg in legs
            if cfg.compensation.target_of(leg) != "drive"]


def prepare_push(request: PushRequest, cfg: StationConfig) -> PreparedRefusal | PreparedTableOperation:
    """A PreparedRefusal (refused before any drive: the legs, the table file, a controller
    target, values that look like a unit slip, against what each leg's holder takes by the
    config) or a PreparedTableOperation whose `lines` say what was accepted and where it goes."""
    from procedures.metrology.plausibility import ImplausibleError
    from station.services.devices import DriverError
    from station.services.session_identity import station_audit_log
    from station.services.table_jobs import check_push_values, controller_refusal, load_leg_table, \
        unverified_table_line

    audit = station_audit_log(cfg, request.audit)
    path = str(request.table) if request.table else None

    def refused(leg: int, exc, source=None, implausible=False) -> PreparedRefusal:
        return PreparedRefusal(PUSH, leg, exc, cfg, audit, source, implausible)

    try:
        legs = parse_legs_text(request.legs)
    except InputError as exc:
        first = int(request.legs) if str(request.legs).isdigit() else 0
        return refused(first, exc, {"path": path} if path else None)
    lines: list[str] = []
    if request.tables is not None:
        tables = {leg: request.tables[leg] for leg in legs}
        sources = {leg: dict((request.sources or {}).get(leg) or {}) for leg in legs}
    else:
        tables, sources = {}, {}
        for leg in legs:
            try:
                tables[leg], sources[leg] = load_leg_table(request.table, leg)
            except (InputError, DriverError, OSError) as exc:
                return refused(leg, exc, {"path": path, "leg": leg})
        unverified = unverified_table_line(request.table, tables, next(iter(sources.values())).get("table_integrity", ""))
        if unverified:  # a file without its integrity record: said once; the push checks it covers the stroke
            lines.append(unverified)
    controller = controller_refusal(cfg, legs, PUSH)
    if controller:
        return refused(controller[0], InputError(controller[1]), sources.get(controller[0]))
    name = request.table_name or path or str((sources.get(legs[0]) or {}).get("path") or "the table")
    try:  # a unit slip (nm in the um columns) never reaches a drive unasked: refused before connecting,
        # against what each leg's holder takes by the config (the push job checks again against the drive's)
        accepted = check_push_values(tables, name, {leg: _configured_limit_um(cfg, leg) for leg in legs},
                                     accept_implausible=request.accept_implausible,
                                     override=accept_override(request.accept_how, request.accepted_as))
    except ImplausibleError as exc:
        return refused(exc.leg, exc, sources.get(exc.leg), implausible=True)
    warned = [line for lines_ in accepted.values() for line in lines_]
    lines += warned
    lines.append(f"drive: {drive_text(cfg)}")
    lines += _target_lines(cfg, legs)  # the plan names every leg's target; said first where it is not the drive
    return PreparedTableOperation(PUSH, request, cfg, legs, audit, tables, sources, warned, lines)


def prepare_rollback(request: RollbackRequest, cfg: StationConfig) -> PreparedRefusal | PreparedTableOperation:
    """A PreparedRefusal (a leg this station does not have, a controller target) or the rollback."""
    from station.services.config import LEG_COUNT
    from station.services.session_identity import station_audit_log
    from station.services.table_jobs import controller_refusal

    audit = station_audit_log(cfg, request.audit)
    leg = int(request.leg)
    if not 1 <= leg <= LEG_COUNT:
        return PreparedRefusal(ROLLBACK, leg, InputError(f"--leg {leg}: leg numbers run from 1 to {LEG_COUNT}"), cfg,
                               audit)
    controller = controller_refusal(cfg, (leg,), ROLLBACK)
    if controller:
        return PreparedRefusal(ROLLBACK, leg, InputError(controller[1]), cfg, audit)
    return PreparedTableOperation(ROLLBACK, request, cfg, (leg,), audit,
                                  lines=[f"drive: {drive_text(cfg)}", *_target_lines(cfg, (leg,))])


def plan_lines(plan, drive_url: bool = True, checksums: bool = True) -> list[str]:
    """What a front end shows of a push or rollback plan (procedures.compensation.push.PushPlan):
    its own lines, without the drive's address (`drive_url` False: a volatile port) or the new
    table's checksum line (`checksums` False: several legs in one dialog)."""
    return plan.describe(drive_url=drive_url, checksums=checksums)


def planned(event: object) -> PushPlan | None:
    """The plan a push or rollback shows before its confirmation, when `event` is it (its
    TablePlanned event), else None."""
    from procedures.compensation.push import TablePlanned

    return event.plan if isinstance(event, TablePlanned) else None


def audit_problem_lines(audit, most: int = 3) -> list[str]:
    """The first damaged lines of the audit log `audit`, one sentence each (left as they are:
    the log is append-only); [] when it cannot be read at all (the job says why)."""
    from procedures.compensation.audit import AuditError

    try:
        _, problems = audit.read()
    except AuditError:
        return []
    return [f"{audit.path}, line {p.line}: {p.reason} (left as is: the log is append-only)" for p in problems[:most]]


def pushed_lines(job: JobOutcome, cfg: StationConfig) -> list[str]:
    """A completed push's lines, one per leg pushed (PushResult.lines): the bank now active, its
    checksum, its target, and a warning when the drive does not apply its table."""
    from procedures.compensation.push import OperationFinished
    from station.services.table_jobs import target_text

    return [line for end in job.of(OperationFinished) if end.leg is not None and end.result is not None
            for line in end.result.lines(target_text(cfg, end.result.leg))]


def rolled_back_line(job: JobOutcome) -> str:
    """A completed rollback's line: the bank now active and the table it holds."""
    from procedures.compensation.push import TablePlanned, describe_table

    result = job.finished.result
    plan = job.of(TablePlanned)[-1].plan
    return (f"rolled back: leg {plan.leg} bank {result.bank} active (was bank {result.previous_bank}): "
            f"{describe_table(plan.table)}; sha256 {result.table_sha256}")


CANCELLED_LINE = "cancelled; nothing was written"


def outcome_lines(job: JobOutcome, cfg: StationConfig, audit: AuditLog | None = None) -> list[str]:
    """How a push or rollback ended, in the one wording every front end shows (`station push` and
    `station rollback` print these lines; the Compensation page's notice is them):
    - a push that ended ok: each leg's `pushed_lines` (several legs: then the procedure's line
      for them all), then where the backup is (`audit`'s path);
    - a rollback that ended ok: `rolled_back_line`;
    - cancelled: that nothing was written;
    - refused or failed: the legs pushed before it (several legs), then the procedure's own
      message, last (it says what was written and, after a failure, which table is active)."""
    end = job.finished
    if end is None:
        return ["the operation ended without an outcome"]
    pushed = pushed_lines(job, cfg) if end.action == PUSH else []
    if end.outcome == "ok":
        if end.action == ROLLBACK:
            return [rolled_back_line(job)]
        whole = [end.message] if end.leg is None else []  # several legs: "pushed legs [...]: ..."
        return pushed + whole + [f"backup of the previous table(s) is in "
                                 f"{audit.path if audit is not None else 'the audit log'}"]
    if end.outcome == "cancelled":
        return [CANCELLED_LINE]
    return pushed + [end.message]
