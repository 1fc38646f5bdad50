"""Jobs both front ends start on a drive's compensation table: push, rollback and verify.

Each runs a procedure (procedures.compensation.push, procedures.compensation.verify) through the one runner with the audit
sink (the only writer of the audit log) and the front end's own sinks, and returns what ended
it. The command line and the terminal UI differ only in how they ask for confirmation and how
they show the events, so they give the same refusals, audit lines and figures.

The unit-slip checks (procedures.metrology.plausibility) are made here too: a table correcting more than
the error it was made from (`make_checked_table`) and a push of corrections beyond 100 um, most
likely nm (`push_job`, `push_legs_job`, before anything reaches a drive), are refused unless the
front end passes `accept_implausible=True` (the command line's --accept-implausible, the UI's
confirmation dialog).
"""

from __future__ import annotations

import json
import math
import uuid
from dataclasses import dataclass

from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable, Iterator, Mapping

import numpy as np

from drivers.errors import DriverError
from drivers.interfaces import ServoAxis, TableBank, TableSpec
from procedures.engine import events as ev
from procedures.compensation.audit import AuditLog, AuditSink, AuditStopped
from procedures.engine.control import RunControl
from procedures.vocabulary import InputError
from procedures.acquisition.plans import SweepPlan
from procedures.compensation.push import (
    Confirm,
    PushFailed,
    PushPlan,
    PushRefused,
    PushResult,
    apply_plan,
    finished,
    push_legs_procedure,
    push_procedure,
    quantize,
    refused,
    rollback_procedure,
    table_sha256,
)
from procedures.metrology.plausibility import (
    Implausible,
    ImplausibleError,
    Override,
    check_correction,
    check_table_values,
    settle,
)
from procedures.io.recording.identity import SessionIdentity
from procedures.io.recording.reader import Session, file_sha256
from procedures.io.recording.sink import RecorderSink
from procedures.io.recording.writer import to_json_text
from procedures.engine.runner import ListSink, Sink, run
from procedures.compensation.audit import Action
from procedures.vocabulary import Outcome
from procedures.compensation.table import (
    CompTable,
    LegTable,
    TableIntegrityError,
    check_covers_stroke,
    make_table,
    read_table_csv,
    write_table_csv,
)
from procedures.io.integrity import UNVERIFIED, unverified_line
from procedures.compensation.verify import verify_procedure
from station import __version__
from station.catalog.store import LOCAL_NAME, Catalog
from station.catalog.writer import CatalogSink, catalog_for, enabled, register
from station.services.config import LEG_COUNT, StationConfig
from station.services.session_identity import session_identity
from station.services.job import JobOutcome  # the one outcome of every job
from station.services.wiring import Rig

if TYPE_CHECKING:  # annotations only: the fitting code loads when a table is made
    from procedures.fit.model import LegErrorModel


def run_table_job(procedure: Iterator[ev.Event], audit: AuditLog, sinks: Iterable[Sink] = (),
                  control: RunControl | None = None, catalog: Catalog | None = None,
                  session_path: str | Path | None = None) -> JobOutcome:
    """Run a table procedure with the audit sink (first: an entry is on disk before any other
    sink sees the event that follows it) and `sinks`; the catalog sink indexes the entries (and
    a verification's session) when it closes. `catalog` None: the local one beside the audit log."""
    events = ListSink()
    audit_sink = AuditSink(audit)
    if catalog is None and enabled():
        catalog = Catalog(local=audit.path.parent / LOCAL_NAME)
    catalog_sink = CatalogSink(catalog, session_path, audit_sink)
    result = run(procedure, [audit_sink, events, *sinks, catalog_sink], control)
    end = finished(events.events)
    return JobOutcome(end.outcome if end is not None else Outcome.FAILED, run=result, events=events.events,
                      finished=end, audit_problems=audit_sink.problems)


def run_operation(procedure: Iterator[ev.Event], audit: AuditLog | None = None) -> PushResult:
    """Run a push/rollback procedure through the runner (with an AuditSink on `audit`) and
    return its PushResult; PushRefused (refused, cancelled) or PushFailed (failed; the message
    says which table is active) otherwise. For scripts, the sample sessions and tests: the front
    ends run the jobs below (push_job, rollback_job), which report instead of raising."""
    events = ListSink()
    sinks = [events] + ([AuditSink(audit)] if audit is not None else [])
    try:
        run(procedure, sinks)
    except AuditStopped as exc:  # "started" not stored: nothing written; "ok" not stored: written and active
        raise (PushRefused if exc.entry.outcome == Outcome.STARTED else PushFailed)(str(exc.args[0])) from None
    end = finished(events.events)
    if end is None:
        raise PushFailed("the operation ended without an outcome")
    if end.outcome == Outcome.OK:
        return end.result
    if end.outcome == Outcome.FAILED:
        raise PushFailed(end.message)
    refusal = PushRefused(end.message)
    refusal.hint = ""  # the message already says that nothing was written
    raise refusal


def push_table(axis: ServoAxis, table: TableBank | LegTable | None = None, *, plan: PushPlan | None = None,
               audit: AuditLog | None = None, drive_url: str = "", spec: TableSpec | None = None,
               source: dict[str, Any] | None = None, leg_serial: str | None = None) -> PushResult:
    """Push `table` (a TableBank or LegTable; or an already confirmed `plan` from
    procedures.compensation.push.prepare_push) to `axis`: push_procedure run to its end through
    the runner, every entry appended to `audit` (when given)."""
    if plan is not None:
        return run_operation(apply_plan(axis, plan), audit)
    if table is None:
        raise ValueError("push_table needs a table or a plan")
    return run_operation(push_procedure(axis, table, drive_url=drive_url, source=source, spec=spec,
                                        leg_serial=leg_serial), audit)


def rollback(axis: ServoAxis, audit: AuditLog, *, plan: PushPlan | None = None, drive_url: str = "") -> PushResult:
    """`rollback_procedure` run to its end through the runner (or an already confirmed `plan`), logged in `audit`."""
    if plan is not None:
        return run_operation(apply_plan(axis, plan), audit)
    return run_operation(rollback_procedure(axis, audit, drive_url=drive_url), audit)


# -- compensation targets ----------------------------------------------------------------------------

def controller_refusal(cfg: StationConfig, legs: Iterable[int], action: Action) -> tuple[int, str] | None:
    """(leg, reason) for the first of `legs` whose [compensation] target is `controller`: the
    station neither writes nor verifies its table (the controller applies it); None otherwise."""
    for leg in legs:
        if cfg.compensation.target_of(leg) == "controller":
            return leg, (f"leg {leg}: compensation target is controller ([compensation] in {cfg.source}), so the "
                         f"station does not {action} its table: the controller applies it; export the table for it "
                         "(`station table MODEL.json --format linuxcnc`), or set the leg's target to drive or station")
    return None


def target_text(cfg: StationConfig, leg: int) -> str:
    """How a front end names leg `leg`'s compensation target: "drive", "station (STORE)", "controller"."""
    target = cfg.compensation.target_of(leg)
    return f"station ({cfg.station_tables_path})" if target == "station" else target


# -- push and rollback ---------------------------------------------------------------------------------

def load_leg_table(path: str | Path, leg: int) -> tuple[LegTable, dict[str, Any]]:
    """One leg's rows of a table CSV (from `station table`) and where they came from
    ({"path", "leg", "sha256"}). InputError naming the file when it is malformed, has no rows
    for `leg`, or was made for a platform with more legs than this station drives. Whether the
    drive can hold the table is checked by the push, against what the drive says it holds."""
    if not 1 <= leg <= LEG_COUNT:
        raise InputError(f"--leg {leg}: leg numbers run from 1 to {LEG_COUNT}")
    table = read_table_csv(path, check=False)
    other = [x for x in table.legs if x > LEG_COUNT]
    if other:
        raise InputError(f"{path}: the table has legs {list(table.legs)}, but this station drives legs 1-{LEG_COUNT}: "
                         "it was made for a platform with another leg count; make the table from a model of these legs")
    if leg not in table.legs:
        raise InputError(f"{path}: the table has no rows for leg {leg} (it has legs {list(table.legs)})")
    source = {"path": str(path), "leg": leg, "sha256": file_sha256(path), "table_integrity": table.integrity}
    if table.serials.get(leg):
        source["leg_serial"] = table.serials[leg]  # checked by the push against the leg's serial
    return table.legs[leg], source


def push_job(axis: ServoAxis, table: LegTable, *, audit: AuditLog, drive_url: str, source: dict[str, Any] | None,
             confirm: Confirm | None, sinks: Iterable[Sink] = (), leg_serial: str | None = None,
             catalog: Catalog | None = None, accept_implausible: bool = False, table_name: str | None = None,
             override: Override = Override()) -> JobOutcome:
    """Push one leg's table to its drive (procedures.compensation.push.push_procedure); `leg_serial`: the
    serial the leg carries (config), which the table's must match. Corrections that look like nm
    are refused first (`check_push_values`; `table_name` names the table in the refusal)."""
    refusal, warnings, checked = _plausible_push({axis.leg: axis}, {axis.leg: table}, {axis.leg: source}, audit=audit,
                                                 drive_url=drive_url, sinks=sinks, catalog=catalog,
                                                 accept_implausible=accept_implausible, table_name=table_name,
                                                 override=override)
    if refusal is None:
        refusal = _incomplete_refusal({axis.leg: axis}, {axis.leg: table}, {axis.leg: source}, audit=audit,
                                      drive_url=drive_url, sinks=sinks, catalog=catalog)
    if refusal is not None:
        return refusal
    job = run_table_job(push_procedure(axis, table, confirm=confirm, drive_url=drive_url, source=checked[axis.leg],
                                       leg_serial=leg_serial), audit, sinks, catalog=catalog)
    job.warnings = warnings
    return job


def push_legs_job(axes: dict[int, ServoAxis], tables: dict[int, LegTable], *, audit: AuditLog, drive_url: str,
                  sources: dict[int, dict[str, Any]] | None, confirm, sinks: Iterable[Sink] = (),
                  leg_serials: dict[int, str] | None = None, catalog: Catalog | None = None,
                  accept_implausible: bool = False, table_name: str | None = None,
                  override: Override = Override()) -> JobOutcome:
    """Push several legs' tables after one confirmation (procedures.compensation.push.push_legs_procedure);
    corrections that look like nm in any leg are refused first, nothing written to any leg."""
    refusal, warnings, sources = _plausible_push(axes, tables, sources or {}, audit=audit, drive_url=drive_url,
                                                 sinks=sinks, catalog=catalog, accept_implausible=accept_implausible,
                                                 table_name=table_name, override=override)
    if refusal is None:
        refusal = _incomplete_refusal(axes, tables, sources, audit=audit, drive_url=drive_url, sinks=sinks,
                                      catalog=catalog)
    if refusal is not None:
        return refusal
    job = run_table_job(push_legs_procedure(axes, tables, confirm=confirm, drive_url=drive_url, sources=sources,
                                            leg_serials=leg_serials), audit, sinks, catalog=catalog)
    job.warnings = warnings
    return job


def rollback_job(axis: ServoAxis, *, audit: AuditLog, drive_url: str, confirm: Confirm | None,
                 sinks: Iterable[Sink] = (), catalog: Catalog | None = None) -> JobOutcome:
    """Restore what the drive held before the last successful push (procedures.compensation.push.rollback_procedure)."""
    return run_table_job(rollback_procedure(axis, audit, confirm=confirm, drive_url=drive_url), audit, sinks,
                         catalog=catalog)


def refusal_job(action: Action, leg: int, reason: BaseException | str, *, audit: AuditLog, drive_url: str = "",
                source: dict[str, Any] | None = None, sinks: Iterable[Sink] = (),
                catalog: Catalog | None = None) -> JobOutcome:
    """A refusal found before a drive is reached (a bad table file, a leg the platform does not
    have), logged and reported like any other."""
    return run_table_job(refused(action, leg, reason, drive_url=drive_url, source=source), audit, sinks,
                         catalog=catalog)


# -- integrity: a table file without its record reaches a drive only when it covers the stroke -----------

def unverified_table_line(path: str | Path, tables: Mapping[int, LegTable], integrity: str) -> str | None:
    """The one warning line for legs of a table file read without an integrity record
    (`integrity` UNVERIFIED), else None."""
    if integrity != UNVERIFIED:
        return None
    legs = ", ".join(f"leg {leg}: {t.point_count} rows {t.start_mm:+g} .. {t.end_mm:+g} mm step {t.step_mm:g} mm"
                     for leg, t in tables.items())
    return unverified_line(path, "table", f"{legs}; whole rows, even steps; the push checks it covers the stroke")


def _incomplete_refusal(axes: Mapping[int, ServoAxis], tables: Mapping[int, LegTable], sources: Mapping[int, dict[str, Any] | None], *,
                        audit: AuditLog, drive_url: str, sinks: Iterable[Sink], catalog: Catalog | None):
    """A refusal job (audit line written, nothing sent to any drive) when a leg's table came from
    a file without an integrity record and does not cover the leg's stroke by its drive's soft
    limits (`check_covers_stroke`): a file cut after a whole row. None otherwise; a drive whose
    limits cannot be read is left to the push, which reads them again and says why."""
    for leg, table in tables.items():
        source = sources.get(leg) or {}
        if source.get("table_integrity") != UNVERIFIED or leg not in axes:
            continue
        try:
            if axes[leg].table_spec() is None:
                continue  # a drive holding no table: the push refuses that, offering the other targets
            limits = axes[leg].limits()
        except DriverError:
            continue
        try:
            check_covers_stroke(table, limits, str(source.get("path") or "the table"))
        except TableIntegrityError as exc:
            return refusal_job(Action.PUSH, leg, exc, audit=audit, drive_url=drive_url, source=source, sinks=sinks,
                               catalog=catalog)
    return None


# -- plausibility: a likely unit slip reaches neither a table file nor a drive unasked ------------------

def implausible_corrections(model: LegErrorModel, table: CompTable) -> list[Implausible]:
    """The legs of `table` whose corrections span more than the error `model` was fitted to
    (procedures.metrology.plausibility.check_correction)."""
    source = model.source.get("path") or "the model's recording"
    found = []
    for leg, t in table.legs.items():
        values = np.concatenate([np.asarray(t.error_fwd_um, float), np.asarray(t.error_rev_um, float)])
        finding = check_correction(leg, float(values.max() - values.min()), float(model.legs[leg].stats.range_before_um),
                                   source)
        if finding is not None:
            found.append(finding)
    return found


def heldout_worse(model: LegErrorModel, table: CompTable) -> list[Implausible]:
    """The legs of `table` whose model made the error worse on the cycles held out of its fit
    (a negative held-out range reduction, docs/figures.md): a table from it adds error."""
    found = []
    for leg in table.legs:
        stats = model.legs[leg].stats
        pct = stats.heldout_range_reduction_pct
        if pct is not None and pct < 0:
            found.append(Implausible(
                f"leg {leg}: held-out range reduction (%)", float(pct),
                f"the model made the leg's error worse on the cycles held out of its fit (held-out range "
                f"{stats.heldout_range_um:.3f} um against {stats.range_before_um:.3f} um before): a table from it "
                "adds error; fit again (more cycles, another --method or --params)"))
    return found


def check_table_stroke(model: LegErrorModel, table: CompTable, soft_limits_mm: tuple[float, float] | None, source: str = "") -> None:
    """InputError when a leg of `table` ends beyond the drive's soft limits (min_mm, max_mm): a
    step that does not divide the stroke ends the table up to a step beyond it, where no drive
    holds a table (the push would refuse it later)."""
    if soft_limits_mm is None:
        return
    lo, hi = soft_limits_mm
    for leg, t in table.legs.items():
        if t.start_mm < lo - 1e-6 or t.end_mm > hi + 1e-6:
            a, b = model.legs[leg].stroke_mm
            fits = (b - a) / max(1, math.ceil((b - a) / t.step_mm - 1e-9))
            raise InputError(
                f"leg {leg}: a {t.step_mm:g} mm step makes the table cover {t.start_mm:+g} .. {t.end_mm:+g} mm, beyond "
                f"the drive's soft limits {lo:+g} .. {hi:+g} mm{f' ({source})' if source else ''}; use a step that "
                f"ends within them, e.g. {fits:.6g} mm (a whole number of steps over the {a:+g} .. {b:+g} mm stroke); "
                "nothing was written")


def make_checked_table(model: LegErrorModel, step_mm: float | None = None, spec: TableSpec | None = None, *,
                       legs: Iterable[int] | None = None, accept_implausible: bool = False,
                       override: Override = Override(),
                       soft_limits_mm: tuple[float, float] | None = None) -> tuple[CompTable, list[str]]:
    """The table of `model` (procedures.compensation.table.make_table) and the warning lines of what was
    accepted; ImplausibleError (nothing is made) when its corrections span far more than the
    recorded error did, or its model made a leg worse on held-out data, unless
    `accept_implausible`; InputError when it ends beyond `soft_limits_mm` (the drive's, when
    known). Both front ends make tables through this."""
    table = make_table(model, step_mm, spec, legs=legs)
    check_table_stroke(model, table, soft_limits_mm)
    found = implausible_corrections(model, table) + heldout_worse(model, table)
    return table, settle(found, accept_implausible, override=override)


@dataclass
class TableAttempt:
    """A table made for a page that shows a unit-slip refusal and offers to accept it: `table` and
    the `warnings` of what was accepted, or `table` None and `refused` the refusal's text (the
    ImplausibleError of make_checked_table; nothing was made)."""

    table: CompTable | None
    warnings: list[str]
    refused: str | None = None


def attempt_checked_table(model, step_mm: float | None = None, spec: TableSpec | None = None, *,
                          accept_implausible: bool = False, override: Override = Override()) -> TableAttempt:
    """make_checked_table with its unit-slip refusal as data (the TUI's Compensation page says it
    and asks whether to accept it); any other refusal (InputError) is raised as there."""
    try:
        table, warnings = make_checked_table(model, step_mm, spec, accept_implausible=accept_implausible,
                                             override=override)
    except ImplausibleError as exc:
        return TableAttempt(None, [], str(exc))
    return TableAttempt(table, warnings)


def check_push_values(tables: Mapping[int, LegTable], table_name: str, limits_um: Mapping[int, float], *,
                      accept_implausible: bool = False, override: Override = Override()) -> dict[int, list[str]]:
    """Refuse (ImplausibleError, its `leg` set) a leg's corrections beyond 100 um and within
    `limits_um[leg]` (what its holder takes; beyond, the push's own refusal), most likely nm in
    the um columns, unless `accept_implausible`; else each leg's warning lines of what was accepted."""
    warnings: dict[int, list[str]] = {}
    for leg, t in tables.items():
        found = check_table_values(t, table_name, limits_um.get(leg, float("inf")))
        try:
            lines = settle([found] if found else [], accept_implausible, "", override)  # the refusal adds it
        except ImplausibleError as exc:
            exc.leg = leg
            raise
        if lines:
            warnings[leg] = lines
    return warnings


def _limit_um(axis: ServoAxis) -> float:
    """The largest correction `axis`'s table holder takes (inf when unknown: the push says why)."""
    try:
        spec = axis.table_spec()
    except Exception:  # noqa: BLE001 (the push reads it again and refuses with the drive's own reason)
        return float("inf")
    return spec.max_correction_um if spec is not None else float("inf")


def _plausible_push(axes: Mapping[int, ServoAxis], tables: Mapping[int, LegTable], sources: Mapping[int, dict[str, Any] | None], *,
                    audit: AuditLog, drive_url: str, sinks: Iterable[Sink], catalog: Catalog | None,
                    accept_implausible: bool, table_name: str | None, override: Override):
    """(refusal job, [], sources) when a leg's values look like a unit slip and were not accepted,
    its audit line written and nothing sent to a drive; else (None, warning lines, the sources
    with what each leg's user accepted, for its audit entries)."""
    first = (sources.get(min(tables)) or {}) if tables else {}
    name = table_name or str(first.get("path") or "the table")
    try:
        accepted = check_push_values(tables, name, {leg: _limit_um(axes[leg]) for leg in tables if leg in axes},
                                     accept_implausible=accept_implausible, override=override)
    except ImplausibleError as exc:
        job = refusal_job(Action.PUSH, exc.leg, exc, audit=audit, drive_url=drive_url, source=sources.get(exc.leg),
                          sinks=sinks, catalog=catalog)
        job.implausible = True
        return job, [], dict(sources)
    out = {leg: ({**(s or {}), "implausible_accepted": accepted[leg]} if leg in accepted else s)
           for leg, s in sources.items()}
    return None, [line for lines in accepted.values() for line in lines], out


# -- verify ------------------------------------------------------------------------------------------

def expected_tables(path: str | Path, legs: Iterable[int], spec: TableSpec) -> dict[int, str]:
    """sha256 of each leg's rows of a table CSV as the drive would hold them (for `verify --table`)."""
    table = read_table_csv(path, spec)
    missing = [leg for leg in legs if leg not in table.legs]
    if missing:
        raise InputError(f"{path}: no rows for leg(s) {missing} (it has legs {list(table.legs)})")
    return {leg: table_sha256(quantize(table.legs[leg].to_bank(), spec)) for leg in legs}


def verify_job(rig: Rig, plan: SweepPlan, out: str | Path, cfg: StationConfig, *, audit: AuditLog,
               before: Session | None = None, expected_sha256: dict[int, str] | None = None,
               expected_source: str = "the table", drive_url: str = "", sinks: Iterable[Sink] = (),
               control: RunControl | None = None, normalise: bool = True,
               identity: SessionIdentity | None = None) -> JobOutcome:
    """A verification sweep of `plan` with the tables active, recorded to `out`, compared with the
    calibration `before` (procedures.compensation.verify.verify_procedure); errors normalised to 20 degC
    unless `normalise` is False. `identity`: the session's (None: station.services.session_identity.session_identity
    of the rig's legs now)."""
    out = Path(out)
    if out.exists():
        raise InputError(f"{out}: exists; choose another file (a verification is a new session)")
    out.parent.mkdir(parents=True, exist_ok=True)
    # a verification is a session too: it records who and what it measured, and warns about the laser
    identity = identity or session_identity(cfg, plan.legs, rig.axes, __version__)
    station_config = as_recorded("station_config", cfg.to_dict())
    recorder = RecorderSink(out, operator=cfg.operator, rig=rig.kind, station_config=station_config,
                            software_version=__version__, identity=identity.to_json())
    # the figures come from the points as measured, with the config as recorded; the file's
    # hash names the recording (the catalog sink indexes the file itself when it closes)
    procedure = verify_procedure(rig.axes, rig.laser, rig.clock, plan, out, recording_sha256=file_sha256,
                                 station_config=station_config, before=before,
                                 expected_sha256=expected_sha256, expected_source=expected_source, drive_url=drive_url,
                                 control=control, normalise=normalise,
                                 sweep_options={"session_id": uuid.uuid4().hex[:12], "warnings": identity.warnings})
    return run_table_job(procedure, audit, [recorder, *sinks], control, catalog=catalog_for(cfg), session_path=out)


def as_recorded(name: str, value: dict[str, Any]) -> dict[str, Any]:
    """`value` as a session records it in /meta (`name`: "station_config", "identity") and a
    reader reads it back: the same JSON, so a figure of the points as measured equals the
    figure of the file."""
    return json.loads(to_json_text(name, value))


class OperationFailed(DriverError):
    """A push or rollback failed after it started writing (the message says which table is active)."""


def write_table(table: CompTable, out: str | Path, cfg: StationConfig, spec: TableSpec | None = None) -> Path:
    """Write `table` as CSV (validated against `spec`) and index it in the catalog of `cfg`; both
    front ends write table CSVs through this (a catalog that cannot be written never fails it)."""
    path = write_table_csv(table, out, spec)
    register(catalog_for(cfg), path, "table")
    return path
