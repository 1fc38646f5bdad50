"""Pushing a compensation table to a drive safely, and rolling it back.

Pure logic over the `ServoAxis` interface (drivers.interfaces): any drive with two table banks
works, real, simulated or replayed. The safe path, for a push and for a rollback alike:

1. Refuse while the axis moves. Read the drive's identity, its active bank and the table in it
   (the backup). Check the new table against the drive's limits (points, step, range within
   the soft limits, largest correction). Nothing is written when any of this fails.
2. Append the backup (entries in full) to the audit log, outcome "started", *before* writing:
   a crash later can never lose the table that was active.
3. Write the INACTIVE bank (the drive refuses writes to the active one; `write_table` sends the
   entries in chunks of <= 123 registers and the header with its checksum last, then reads
   everything back and compares). Read the bank back again through the interface and compare
   its content hash with what was meant to be written.
4. Activate it (one write: the drive re-checks the checksum and refuses while moving), and
   confirm the drive reports the new bank active.
5. Append the outcome. On any failure before the switch the previous table is still active,
   because the drive only changes tables on the activation write; the error says so, and says
   honestly when the state could not be confirmed.

Compensation targets (docs/compensation.md): the same procedures serve a leg whose table the
drive holds (target "drive") and a leg whose table the station applies to every command
(target "station": drivers/station_compensation.py, a ServoAxis with the same two banks, wired
in station/services/wiring.py). `compensation_target(axis)` tells them apart; the plan shows it, every
audit entry records it in `details["target"]`, and a rollback only restores a push made to the
same target.

Leg identity: a table made from a session names the serial of the leg it was made for
(`source["leg_serial"]`, from the table CSV's `# leg_serial:` line). The station knows which leg
serial each drive's leg carries from its config (`[legs.N] serial`, or its serials file), passed
as `leg_serial`. When both are known and differ the push is refused first, before the drive is
even read: the correction of one ball screw applied to another would make that leg worse. When
either is unknown the push goes on and the plan says the serial was not checked.

Conventions: table entries are predicted errors (measured minus commanded, um) that the drive
subtracts; positions mm. `table_sha256` is the hash of a table's content as the drive stores it
(entries quantised to the drive's resolution), so a table read back from a drive hashes the
same as the one pushed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator

from drivers.errors import DriverError, TableError, TableRefused
from drivers.interfaces import ServoAxis, TableBank, TableSpec, table_sha256
from procedures.engine import events as ev
from procedures.compensation.applied_table import compensation_target, target_details
from procedures.compensation.audit import AuditEntry, AuditLog, AuditRecord, new_id
from procedures.vocabulary import InputError
from procedures.compensation.audit import Action
from procedures.vocabulary import Outcome
from procedures.compensation.table import LegTable

QUANTUM_UM = 0.01
"""Default entry resolution of a drive table, um per count (drive profile [table] entry_scale_um)."""



class PushRefused(DriverError):
    """A push or rollback was refused before anything was written to the drive."""

    hint = "Nothing was written to the drive."


class PushFailed(TableError):
    """A push or rollback failed after it started writing; the message says which table is active."""

    hint = ""


# -- table content -----------------------------------------------------------------------------

def quantize(table: TableBank, quantum_um: float | TableSpec = QUANTUM_UM) -> TableBank:
    """`table` as a drive holding entries in `quantum_um` um steps (or as `TableSpec`) stores it:
    see `TableSpec.quantize`."""
    spec = quantum_um if isinstance(quantum_um, TableSpec) else TableSpec(entry_resolution_um=quantum_um)
    if not spec.entry_resolution_um > 0:
        raise ValueError(f"quantum_um must be > 0, got {spec.entry_resolution_um}")
    return spec.quantize(table)


def table_to_json(table: TableBank, bank: int | None = None) -> dict[str, Any]:
    """A table in full, for the audit log (the backup a rollback restores)."""
    return {
        "bank": bank,
        "start_mm": float(table.start_mm),
        "spacing_mm": float(table.spacing_mm),
        "error_fwd_um": [float(v) for v in table.error_fwd_um],
        "error_rev_um": [float(v) for v in table.error_rev_um],
        "checksum": int(table.checksum),
        "sha256": table_sha256(table),
    }


def table_from_json(d: Any, where: str = "backup") -> TableBank:
    """The TableBank of `table_to_json` output. PushRefused naming `where` when it is malformed or
    its entries do not match its recorded hash."""
    try:
        fwd = tuple(float(v) for v in d["error_fwd_um"])
        rev = tuple(float(v) for v in d["error_rev_um"])
        table = TableBank(float(d["start_mm"]), float(d["spacing_mm"]), fwd, rev, int(d.get("checksum") or 0))
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise PushRefused(f"{where}: the backed-up table is malformed ({exc!r}); it cannot be restored.") from None
    if len(fwd) != len(rev) or not all(math.isfinite(v) for v in fwd + rev):
        raise PushRefused(f"{where}: the backed-up table has unequal or non-finite entries; it cannot be restored.")
    want = d.get("sha256")
    if want and table_sha256(table) != want:
        raise PushRefused(f"{where}: the backed-up table does not match its recorded sha256 (the audit log was "
                          "altered?); it cannot be restored.")
    return table


def describe_table(table: TableBank) -> str:
    """'N points, START .. END mm step S mm, largest correction C um' (or 'empty (no correction)')."""
    n = table.point_count
    if n == 0:
        return "empty (no correction)"
    end = table.start_mm + (n - 1) * table.spacing_mm
    worst = max(abs(v) for v in table.error_fwd_um + table.error_rev_um)
    return (f"{n} points, {table.start_mm:+.3f} .. {end:+.3f} mm step {table.spacing_mm:g} mm, "
            f"largest correction {worst:.3f} um")


def _as_bank(table: TableBank | LegTable) -> TableBank:
    return table.to_bank() if isinstance(table, LegTable) else table


def _message(exc: BaseException) -> str:
    """A driver error's sentence without its generic hint (we say what is active ourselves); a
    file error as "FILE: what"."""
    if isinstance(exc, OSError) and exc.filename:
        return f"{exc.filename}: {(exc.strerror or str(exc)).lower()}"
    text = str(exc.args[0]) if isinstance(exc, DriverError) and exc.args else str(exc)
    return text.rstrip(". ")


def _short(sha: str) -> str:
    return sha[:12]


# -- plans and results -------------------------------------------------------------------------

@dataclass(frozen=True)
class PushPlan:
    """What a push (or rollback) will do, read from the drive; nothing written yet.

    `table` is the table as the drive will hold it (quantised), `backup` the drive's active
    table now (bank `active_bank`), `target_bank` the inactive bank to write.
    """

    action: Action
    leg: int
    drive: str
    drive_url: str
    table: TableBank
    table_sha256: str
    active_bank: int
    target_bank: int
    backup: TableBank
    backup_sha256: str
    table_enabled: bool
    source: dict[str, Any] | None = None
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def target(self) -> str:
        """The leg's compensation target: "drive" (its table banks) or "station"."""
        return str(self.details.get("target", "drive"))

    def describe(self, drive_url: bool = True, checksums: bool = True) -> list[str]:
        """Lines for the confirmation: leg, drive, target, what is written, what is replaced.
        `drive_url` False: without the drive's address (a volatile port); `checksums` False:
        without the new table's checksum line (several legs in one confirmation)."""
        verb = "restore" if self.action == Action.ROLLBACK else "write"
        lines = [
            f"leg {self.leg}: drive {self.drive}" + (f" at {self.drive_url}" if self.drive_url and drive_url else ""),
            f"  target:   {self.target}" + (f" (the station applies the table to every command; tables in "
                                            f"{self.details.get('store')})" if self.target == "station"
                                            else " (the drive's table banks)"),
            f"  {verb}:    {describe_table(self.table)}",
        ]
        if checksums:
            lines.append(f"            sha256 {self.table_sha256}, into bank {self.target_bank} (inactive), then "
                         "switch to it")
        lines.append(f"  replaces: bank {self.active_bank}, {describe_table(self.backup)}, sha256 "
                     f"{_short(self.backup_sha256)}…")
        if self.table_sha256 == self.backup_sha256:
            lines.append("  note: the drive's active table already holds exactly this table")
        made_for, carries = (self.source or {}).get("leg_serial"), self.details.get("leg_serial")
        if made_for and carries:
            lines.append(f"  serial:   leg serial {carries}, the table was made for it")
        elif made_for:
            lines.append(f"  note: the table was made for leg serial {made_for}; the serial of leg {self.leg} is not "
                         f"configured ([legs.{self.leg}] serial), so it was not checked")
        if not self.table_enabled:
            lines.append(f"  note: {not_applied(self.leg, self.target)}; the table is stored but not applied")
        return lines

    def question(self) -> str:
        """The confirmation question, naming the leg."""
        return (f"Push this table to leg {self.leg}?" if self.action == Action.PUSH
                else f"Restore the previous table on leg {self.leg}?")


@dataclass(frozen=True)
class PushResult:
    """A completed push or rollback: `bank` is now active, `previous_bank` held the backup."""

    action: Action
    leg: int
    drive: str
    bank: int
    previous_bank: int
    table_sha256: str
    previous_sha256: str
    points: int
    table_enabled: bool
    op_id: str

    def event(self) -> TablePushed:
        return TablePushed(self.leg, self.bank, self.table_sha256, self.drive)

    def lines(self, target: str = "") -> list[str]:
        """What a completed push says, every front end alike: the bank now active, the table's
        checksum (`target`: where the compensation is applied, in words), and a warning when the
        drive does not apply the table."""
        out = [f"pushed: leg {self.leg} bank {self.bank} active (was bank {self.previous_bank}); table sha256 "
               f"{self.table_sha256}" + (f"; compensation target {target}" if target else "")]
        if not self.table_enabled:
            out.append(f"warning: {not_applied(self.leg)}; switch it on before relying on it")
        return out


def not_applied(leg: int, target: str = "drive") -> str:
    """The words for a leg whose table holder (`target`: "drive" or "station") does not apply
    its table: the plan's note before a push and the warning after it."""
    holder = "the station" if target == "station" else "the drive"
    return f"{holder} does not apply leg {leg}'s table (table compensation off)"


Confirm = Callable[[PushPlan], bool]
"""Asks the operator to confirm a plan (front ends: a prompt, a dialog). May raise InputError
when nobody can answer (no terminal): that refuses the operation."""


# -- events ----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class TablePlanned(ev.Event):
    """A push or rollback read the drive and checked the table (a PushPlan):
    what will be written and what it replaces. Nothing is written yet; the procedure asks for
    confirmation next."""

    plan: PushPlan


@dataclass(frozen=True)
class TablePushed(ev.Event):
    """A push or rollback switched `leg`'s drive to `bank`, which holds the table hashed `table_sha256`."""

    leg: int
    bank: int
    table_sha256: str
    drive: str


@dataclass(frozen=True)
class OperationFinished(ev.Event):
    """A push, rollback or verification ended. `action`: procedures.compensation.audit.Action; `outcome`:
    procedures.vocabulary.Outcome (ok / refused / cancelled / failed for a push or rollback;
    refused / completed / aborted / failed for a verification). `message` says what happened
    and, after a failed push, which table is active. `result`: a push's PushResult; a
    verification's figures per leg (procedures.compensation.verify.LegVerification, which imports this module)."""

    action: str
    leg: int | None
    outcome: str
    message: str
    result: PushResult | dict | None = None


# -- reading the drive ---------------------------------------------------------------------------

def _read_state(axis: ServoAxis, what: str) -> tuple[str, int, TableBank, bool]:
    """(identity, active bank, active table, table enabled); PushRefused if the axis moves or
    the drive's state cannot be read."""
    leg = axis.leg
    try:
        st = axis.status()
        if st.moving:
            raise PushRefused(f"leg {leg}: the axis is moving (at {st.position_mm:+.4f} mm); {what} only at standstill. "
                              "Wait for the move to end or stop it.")
        identity = axis.identity()
        active = axis.active_bank()
        if active not in (0, 1):
            raise PushRefused(f"leg {leg}: the drive reports active bank {active}; only two-bank drives (0/1) are supported.")
        current = axis.read_table(active)
    except PushRefused:
        raise
    except DriverError as exc:
        raise PushRefused(f"leg {leg}: cannot read the drive's state before the {what} ({_message(exc)}).") from None
    return identity, active, current, st.table_enabled


def drive_table_spec(axis: ServoAxis, what: str = "push") -> TableSpec:
    """What `axis` holds; PushRefused when it holds no table bank this station can write."""
    spec = axis.table_spec()
    if spec is None:
        raise PushRefused(f"leg {axis.leg}: this drive holds no compensation table, so there is nothing to {what} "
                          "with compensation target drive; choose target station (the station applies the table to "
                          f"every command: [compensation] legs = {{ {axis.leg} = \"station\" }} in the config) or "
                          "controller (files for the motion controller: `station table --format linuxcnc`).")
    if spec.banks < 2:
        raise PushRefused(f"leg {axis.leg}: the drive holds {spec.banks} table bank(s); a safe {what} needs two "
                          "(write the inactive one, then switch).")
    return spec


def check_leg_serial(leg: int, source: dict[str, Any] | None, leg_serial: str | None) -> None:
    """PushRefused naming both serials when the table (its `source["leg_serial"]`) was made for
    another leg than the one `leg` carries (`leg_serial`); nothing when either is unknown."""
    made_for = (source or {}).get("leg_serial")
    if made_for and leg_serial and made_for != leg_serial:
        path = (source or {}).get("path")
        raise PushRefused(f"leg {leg}: the table{f' {path}' if path else ''} was made for leg serial {made_for}, but "
                          f"leg {leg} carries serial {leg_serial}; push the table made for {leg_serial} (or correct "
                          f"[legs.{leg}] serial if the leg was exchanged)")


def prepare_push(axis: ServoAxis, table: TableBank | LegTable, *, spec: TableSpec | None = None,
                 drive_url: str = "", source: dict[str, Any] | None = None, leg_serial: str | None = None) -> PushPlan:
    """Read the drive and check `table` for it; writes nothing. PushRefused if the table was made
    for another leg serial than `leg_serial` (checked first, `check_leg_serial`), if the axis moves
    or the drive cannot be read; TableRefused if the table does not fit the drive
    (`TableSpec.check`: `spec`, default what the drive says it holds, and its soft limits)."""
    check_leg_serial(axis.leg, source, leg_serial)
    spec = spec or drive_table_spec(axis)
    bank_table = spec.quantize(_as_bank(table))
    identity, active, current, enabled = _read_state(axis, "push")
    try:
        limits = axis.limits()
    except DriverError as exc:
        raise PushRefused(f"leg {axis.leg}: cannot read the drive's soft limits ({_message(exc)}).") from None
    where = f"leg {axis.leg}"
    if source and source.get("path"):
        where = f"{source['path']}, {where}"
    spec.check(bank_table, where, limits, table.point_name if isinstance(table, LegTable) else None)
    details = target_details(axis)
    if leg_serial:
        details["leg_serial"] = leg_serial
    return PushPlan(Action.PUSH, axis.leg, identity, drive_url, bank_table, table_sha256(bank_table), active, 1 - active,
                    current, table_sha256(current), enabled, source, details)


def prepare_rollback(axis: ServoAxis, audit: AuditLog, *, drive_url: str = "") -> PushPlan:
    """What a rollback would restore: the backup of the last successful push of this leg to this
    drive (by identity) in `audit` (read only). Writes nothing. PushRefused when there is none,
    when the drive's active table is not the one that push wrote (changed since, or already
    rolled back), or when the backup is damaged."""
    drive_table_spec(axis, "roll back")
    identity, active, current, enabled = _read_state(axis, "rollback")
    leg = axis.leg
    target = compensation_target(axis)

    def same_target(e: AuditEntry) -> bool:  # entries before targets existed were all drive pushes
        return str((e.details or {}).get("target", "drive")) == target

    current_sha = table_sha256(current)
    entries = audit.entries()
    push = None
    for i in range(len(entries) - 1, -1, -1):
        e = entries[i]
        if (e.action == Action.PUSH and e.outcome == Outcome.OK and e.leg == leg and e.drive == identity
                and same_target(e)):
            push, push_at = e, i
            break
    if push is None:
        raise PushRefused(f"leg {leg}: the audit log {audit.path} has no successful push to drive {identity} "
                          f"with compensation target {target}; there is nothing to roll back.")
    if push.table_sha256 != current_sha:
        for later in entries[push_at + 1:]:
            if (later.action == Action.ROLLBACK and later.outcome == Outcome.OK and later.leg == leg
                    and later.drive == identity and later.table_sha256 == current_sha and same_target(later)):
                raise PushRefused(f"leg {leg}: already rolled back at {later.time_utc}: the active table is the one from "
                                  f"before the push of {push.time_utc}. To use the pushed table again, push it again.")
        raise PushRefused(f"leg {leg}: the drive's active table (sha256 {_short(current_sha)}…) is not the table the last "
                          f"push wrote ({_short(push.table_sha256)}…, {push.time_utc}): it was changed outside this audit "
                          f"log ({audit.path}), so its backup would not undo the right change.")
    restore = table_from_json(push.backup, where=f"{audit.path}, push of {push.time_utc}")
    return PushPlan(Action.ROLLBACK, leg, identity, drive_url, restore, table_sha256(restore), active, 1 - active,
                    current, current_sha, enabled, push.source,
                    {**target_details(axis), "rolls_back": push.op_id or push.id, "push_time_utc": push.time_utc})


# -- the procedures ------------------------------------------------------------------------------

def push_procedure(axis: ServoAxis, table: TableBank | LegTable, *, confirm: Confirm | None = None,
                   drive_url: str = "", source: dict[str, Any] | None = None,
                   spec: TableSpec | None = None, leg_serial: str | None = None) -> Iterator[ev.Event]:
    """Push `table` to `axis` the safe way (module docstring), as events for the one runner.

    Yields `TablePlanned` (what will be written; `confirm(plan)` is then asked, None = confirmed),
    `AuditRecord`s (the audit sink writes them: "started" with the backup before any write,
    then the final one) and ends with `OperationFinished` (ok / refused / cancelled / failed;
    its message says which table is active). On ok a `TablePushed` comes before it.
    """
    try:
        plan = prepare_push(axis, table, spec=spec, drive_url=drive_url, source=source, leg_serial=leg_serial)
    except (PushRefused, TableRefused) as exc:
        yield from refused(Action.PUSH, axis.leg, exc, drive=_identity(axis), drive_url=drive_url, source=source,
                           details=target_details(axis))
        return
    yield from _confirm_andapply_plan(axis, plan, confirm)


def push_legs_procedure(axes: dict[int, ServoAxis], tables: dict[int, TableBank | LegTable], *,
                        confirm: Callable[[list[PushPlan]], bool] | None = None, drive_url: str = "",
                        sources: dict[int, dict[str, Any]] | None = None,
                        leg_serials: dict[int, str] | None = None) -> Iterator[ev.Event]:
    """Push several legs' tables with one confirmation (a whole platform after a calibration).

    Every leg is read and checked first; if any leg is refused, nothing is written to any leg.
    Then one `confirm(plans)` (None = confirmed) and the legs are pushed in turn, each the safe
    way with its own audit entries and `OperationFinished`. A failed leg stops the rest (they
    keep their tables). Ends with an `OperationFinished` for the whole (leg None): ok when every
    leg is, else the first refusal or failure.
    """
    sources = sources or {}
    plans: list[PushPlan] = []
    for leg in sorted(tables):
        try:
            plans.append(prepare_push(axes[leg], tables[leg], drive_url=drive_url, source=sources.get(leg),
                                      leg_serial=(leg_serials or {}).get(leg)))
        except (PushRefused, TableRefused) as exc:
            yield from refused(Action.PUSH, leg, exc, drive=_identity(axes[leg]), drive_url=drive_url,
                               source=sources.get(leg), details=target_details(axes[leg]))
            yield OperationFinished(Action.PUSH, None, Outcome.REFUSED,
                                       f"{_message(exc)}; nothing was written to any leg")
            return
    for plan in plans:
        yield TablePlanned(plan)
    if confirm is not None:
        try:
            ok = confirm(plans)
        except InputError as exc:
            for plan in plans:
                yield from refused(plan.action, plan.leg, exc, drive=plan.drive, drive_url=plan.drive_url, source=plan.source,
                               details={"target": plan.target})
            yield OperationFinished(Action.PUSH, None, Outcome.REFUSED, _message(exc))
            return
        if not ok:
            for plan in plans:
                yield from refused(plan.action, plan.leg, "cancelled at the confirmation; nothing written", drive=plan.drive,
                                   drive_url=plan.drive_url, source=plan.source, outcome=Outcome.CANCELLED,
                               details={"target": plan.target})
            yield OperationFinished(Action.PUSH, None, Outcome.CANCELLED, "cancelled; nothing was written")
            return
    done: list[int] = []
    for plan in plans:
        end: OperationFinished | None = None
        for event in apply_plan(axes[plan.leg], plan):
            if isinstance(event, OperationFinished):
                end = event
            yield event
        if end is None or end.outcome != Outcome.OK:
            left = [p.leg for p in plans if p.leg != plan.leg and p.leg not in done]
            yield OperationFinished(Action.PUSH, None, end.outcome if end else Outcome.FAILED,
                                       f"{end.message if end else 'no outcome'}"
                                       + (f" Pushed before it: legs {done}." if done else "")
                                       + (f" Not attempted: legs {left} (their tables are unchanged)." if left else ""))
            return
        done.append(plan.leg)
    yield OperationFinished(Action.PUSH, None, Outcome.OK, f"pushed legs {done}: each has its new table active")


def rollback_procedure(axis: ServoAxis, audit: AuditLog, *, confirm: Confirm | None = None,
                       drive_url: str = "") -> Iterator[ev.Event]:
    """Restore the table that was active before the last successful push of this leg to this
    drive (found in `audit`, read only), the same safe way as a push; events as `push_procedure`."""
    try:
        plan = prepare_rollback(axis, audit, drive_url=drive_url)
    except (PushRefused, InputError) as exc:
        yield from refused(Action.ROLLBACK, axis.leg, exc, drive=_identity(axis), drive_url=drive_url,
                           details=target_details(axis))
        return
    yield from _confirm_andapply_plan(axis, plan, confirm)


def refused(action: Action, leg: int, reason: BaseException | str, *, drive: str = "", drive_url: str = "",
            source: dict[str, Any] | None = None, outcome: Outcome = Outcome.REFUSED,
            details: dict[str, Any] | None = None) -> Iterator[ev.Event]:
    """A refusal (or a cancellation) as events: its audit entry, then `OperationFinished`. Also
    what a front end runs for a refusal it finds before a drive is reached (a bad table file).
    `details` go into the audit entry (the compensation target, `{"target": ...}`)."""
    text = _message(reason) if isinstance(reason, BaseException) else str(reason)
    if outcome == Outcome.REFUSED and "written" not in text:
        text += ". Nothing was written to the drive."
    yield AuditRecord(AuditEntry(action, leg, outcome, text, drive, drive_url, source=source,
                                    details=dict(details or {})))
    yield OperationFinished(action, leg, outcome, text)


def _identity(axis: ServoAxis) -> str:
    """The drive's identity for a refusal's audit entry; best effort (the refusal matters more)."""
    try:
        return axis.identity()
    except Exception:
        return ""


def _confirm_andapply_plan(axis: ServoAxis, plan: PushPlan, confirm: Confirm | None) -> Iterator[ev.Event]:
    yield TablePlanned(plan)
    if confirm is not None:
        try:
            ok = confirm(plan)
        except InputError as exc:  # nobody can answer: refuse rather than guess
            yield from refused(plan.action, plan.leg, exc, drive=plan.drive, drive_url=plan.drive_url, source=plan.source,
                               details={"target": plan.target})
            return
        if not ok:
            yield from refused(plan.action, plan.leg, "cancelled at the confirmation; nothing written", drive=plan.drive,
                               drive_url=plan.drive_url, source=plan.source, outcome=Outcome.CANCELLED,
                               details={"target": plan.target})
            return
    yield from apply_plan(axis, plan)


def apply_plan(axis: ServoAxis, plan: PushPlan) -> Iterator[ev.Event]:
    leg, bank, prev = plan.leg, plan.target_bank, plan.active_bank
    op_id = new_id()
    base = dict(action=plan.action, leg=leg, drive=plan.drive, drive_url=plan.drive_url,
                table_sha256=plan.table_sha256, bank=bank, previous_bank=prev, source=plan.source,
                details=dict(plan.details), op_id=op_id, backup=table_to_json(plan.backup, prev))
    verb = "rollback" if plan.action == Action.ROLLBACK else "push"
    # the audit sink has this on disk before the runner resumes us: a crash can never lose the backup
    yield AuditRecord(AuditEntry(outcome=Outcome.STARTED,
                                    message=f"{verb} to bank {bank} started; backup of bank {prev} recorded", **base))

    def finish(outcome: Outcome, text: str) -> Iterator[ev.Event]:
        yield AuditRecord(AuditEntry(outcome=outcome, message=text, **base))
        yield OperationFinished(plan.action, leg, outcome, text)

    # the drive may have changed since the plan was made (another station, the drive panel)
    try:
        identity, active, current, _ = _read_state(axis, verb)
    except PushRefused as exc:
        yield from finish(Outcome.REFUSED, f"{_message(exc)}. {PushRefused.hint}")
        return
    if identity != plan.drive or active != prev or table_sha256(current) != plan.backup_sha256:
        yield from finish(Outcome.REFUSED, f"leg {leg}: the drive changed since its table was read (active bank "
                                                f"{active}, was {prev}); read it again and retry. {PushRefused.hint}")
        return

    def failed(stage: str, exc: BaseException, state: str) -> Iterator[ev.Event]:
        yield from finish(Outcome.FAILED,
                          f"leg {leg}: {verb} to drive {plan.drive} failed while {stage}: {_message(exc)}. {state}")

    stage = f"writing bank {bank}"
    try:
        axis.write_table(bank, plan.table)
        stage = f"reading bank {bank} back"
        back = axis.read_table(bank)
        if table_sha256(back) != plan.table_sha256:
            raise TableError(f"bank {bank} reads back as a different table (sha256 {_short(table_sha256(back))}…, "
                             f"expected {_short(plan.table_sha256)}…)")
    except DriverError as exc:
        yield from failed(stage, exc, _previous_state(axis, plan, f"The previous table (bank {prev}, sha256 "
                                      f"{_short(plan.backup_sha256)}…) is still active: the drive only switches tables on "
                                      "the activation, which was not sent"))
        return
    note = ""
    try:
        axis.activate_table(bank)
    except TableError as exc:  # the drive answered with a refusal: nothing switched
        yield from failed(f"activating bank {bank}", exc, _previous_state(
            axis, plan, f"The drive refused the switch: the previous table (bank {prev}) is still active"))
        return
    except DriverError as exc:  # no answer: find out whether the switch landed
        state, text = _state_after_activation(axis, bank, prev, plan.table_sha256, plan.backup_sha256)
        if state != "new":
            yield from failed(f"activating bank {bank}", exc, text)
            return
        note = f" (the activation request got no answer, but the drive then reported bank {bank} active)"
    else:
        state, text = _state_after_activation(axis, bank, prev, plan.table_sha256, plan.backup_sha256)
        if state != "new":
            yield from failed("confirming the switch", TableError(f"the drive accepted the switch to bank {bank}"), text)
            return
    text = f"{verb} ok: bank {bank} active on leg {leg} ({describe_table(plan.table)}){note}"
    result = PushResult(plan.action, leg, plan.drive, bank, prev, plan.table_sha256, plan.backup_sha256,
                        plan.table.point_count, plan.table_enabled, op_id)
    yield AuditRecord(AuditEntry(outcome=Outcome.OK, message=text, **base))
    yield result.event()
    yield OperationFinished(plan.action, leg, Outcome.OK, text, result)


def _previous_still_active(axis: ServoAxis, prev: int, backup_sha: str) -> bool | None:
    """True when the drive reads back bank `prev` active, holding the backed-up table, twice in
    a row (one reply corrupted on the way cannot fake that); False when it reads otherwise; None
    when it does not answer."""
    try:
        for _ in range(2):
            if axis.active_bank() != prev or table_sha256(axis.read_table(prev)) != backup_sha:
                return False
    except DriverError:
        return None
    return True


def _previous_state(axis: ServoAxis, plan: PushPlan, claim: str) -> str:
    """The sentence for a push that failed before its switch took: `claim` (the previous table is
    active), checked on the drive, since a request garbled on the link can land where it should not."""
    confirmed = _previous_still_active(axis, plan.active_bank, plan.backup_sha256)
    if confirmed:
        return f"{claim} (read back from the drive)."
    if confirmed is None:
        return f"{claim} (the drive did not answer the check that reads it back)."
    return (f"It is NOT known which table is active: the drive does not read back bank {plan.active_bank} holding the "
            f"previous table. Do not use the axis before checking its table (register active_bank, docs/register-map.md).")


def _state_after_activation(axis: ServoAxis, bank: int, prev: int, sha: str, backup_sha: str) -> tuple[str, str]:
    """After an activation request: ("new" | "previous" | "unknown", sentence for the error).
    "previous" only when read back twice (`_previous_still_active`)."""
    try:
        now = axis.active_bank()
        if now == bank and table_sha256(axis.read_table(bank)) == sha:
            return "new", ""
    except DriverError:
        return "unknown", (f"It is NOT known whether the drive switched: it stopped answering. Before moving the axis, "
                           f"read its active bank (register active_bank, docs/register-map.md): {prev} = the previous "
                           f"table, {bank} = the new one.")
    if now == prev and _previous_still_active(axis, prev, backup_sha):
        return "previous", f"The drive reports bank {prev} active: the previous table is still active."
    if now == prev:
        return "unknown", (f"It is NOT known whether the drive switched: bank {prev} read back once, not twice with the "
                           f"previous table. Before moving the axis, read its active bank (register active_bank, "
                           f"docs/register-map.md): {prev} = the previous table, {bank} = the new one.")
    return "unknown", (f"The drive reports bank {now} active but it does not hold the table written; do not use the "
                       "axis before checking its table.")


def finished(events: list[ev.Event]) -> OperationFinished | None:
    """The `OperationFinished` among `events` (the last one), if any."""
    done = [e for e in events if isinstance(e, OperationFinished)]
    return done[-1] if done else None
