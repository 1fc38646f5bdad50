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

Conventions: table entries are predicted errors (measured minus commanded, um) that the drive
subtracts; positions mm. `table_sha256` is the hash of a table's content as the drive stores it
(entries quantised to the drive's resolution), so a table read back from a drive hashes the
same as the one pushed.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from typing import Any

from drivers.errors import DriverError, TableError
from drivers.interfaces import DriveLimits, ServoAxis, TableBank
from procedures.audit import AuditEntry, AuditError, AuditLog, new_id
from procedures.events import TablePushed
from procedures.table import LegTable, TableLimits

QUANTUM_UM = 0.01
"""Default entry resolution of a drive table, um per count (drive profile [table] entry_scale_um)."""

POSITION_TOL_MM = 1e-6


class PushRefused(DriverError):
    """A push or rollback was refused before anything was written to the drive."""

    hint = "Nothing was written to the drive."


class PushFailed(TableError):
    """A push or rollback failed after it started writing; the message says which table is active."""

    hint = ""


# -- table content -----------------------------------------------------------------------------

def quantize(table: TableBank, quantum_um: float = QUANTUM_UM) -> TableBank:
    """`table` with entries rounded to the drive's resolution (`quantum_um` um per count) and
    positions to 1e-6 mm, as the drive will hold it. Checksum cleared (the drive computes it)."""
    if not quantum_um > 0:
        raise ValueError(f"quantum_um must be > 0, got {quantum_um}")
    q = lambda vals: tuple(round(v / quantum_um) * quantum_um if math.isfinite(v) else v for v in vals)  # noqa: E731
    return TableBank(round(table.start_mm, 6), round(table.spacing_mm, 6), q(table.error_fwd_um), q(table.error_rev_um))


def table_sha256(table: TableBank) -> str:
    """SHA-256 (hex) of a table's content: start, spacing (1e-6 mm) and both entry lists
    (1e-4 um), as canonical JSON. Independent of the bank and of the stored checksum."""
    doc = {
        "start_mm": round(float(table.start_mm), 6),
        "spacing_mm": round(float(table.spacing_mm), 6),
        "error_fwd_um": [round(float(v), 4) for v in table.error_fwd_um],
        "error_rev_um": [round(float(v), 4) for v in table.error_rev_um],
    }
    return hashlib.sha256(json.dumps(doc, separators=(",", ":"), sort_keys=True).encode()).hexdigest()


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


def check_table(table: TableBank, leg: int, limits: DriveLimits | None = None,
                table_limits: TableLimits | None = None) -> None:
    """Refuse (PushRefused, naming the leg and the problem) a table the drive should not get:
    unequal directions, fewer than 2 or more than `table_limits.max_points` points, a step that
    is not a finite number >= `min_step_mm`, positions outside the drive's soft limits, or a
    correction beyond +/-`max_correction_um`."""
    tl = table_limits or TableLimits()
    n = len(table.error_fwd_um)
    where = f"leg {leg}"
    if len(table.error_rev_um) != n:
        raise PushRefused(f"{where}: the table has {n} forward but {len(table.error_rev_um)} reverse entries.")
    if n < 2:
        raise PushRefused(f"{where}: the table has {n} point(s); a table needs at least two.")
    if n > tl.max_points:
        raise PushRefused(f"{where}: the table has {n} points, the drive holds at most {tl.max_points}; "
                          "make it with a coarser step (`station table --step`).")
    if not (math.isfinite(table.start_mm) and math.isfinite(table.spacing_mm)) or table.spacing_mm < tl.min_step_mm:
        raise PushRefused(f"{where}: the table step {table.spacing_mm:g} mm is not a number >= the drive's minimum "
                          f"{tl.min_step_mm:g} mm (positions must increase strictly).")
    end = table.start_mm + (n - 1) * table.spacing_mm
    if limits is not None:
        if table.start_mm < limits.min_mm - POSITION_TOL_MM or end > limits.max_mm + POSITION_TOL_MM:
            raise PushRefused(f"{where}: the table covers {table.start_mm:+.3f} .. {end:+.3f} mm, beyond the drive's soft "
                              f"limits {limits.min_mm:+.3f} .. {limits.max_mm:+.3f} mm; make it with a step that ends "
                              "within them (`station table --step`).")
    for name, vals in (("error_fwd_um", table.error_fwd_um), ("error_rev_um", table.error_rev_um)):
        for i, v in enumerate(vals):
            if not math.isfinite(v) or abs(v) > tl.max_correction_um:
                raise PushRefused(f"{where}: {name} at {table.start_mm + i * table.spacing_mm:+.4f} mm (point {i + 1}) is "
                                  f"{v} um, beyond the drive's correction limit of +/-{tl.max_correction_um:g} um.")


def _as_bank(table: TableBank | LegTable) -> TableBank:
    return table.to_bank() if isinstance(table, LegTable) else table


def _message(exc: BaseException) -> str:
    """A driver error's sentence without its generic hint (we say what is active ourselves)."""
    text = str(exc.args[0]) if getattr(exc, "args", None) else str(exc)
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

    action: str  # "push" / "rollback"
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

    def describe(self) -> list[str]:
        """Lines for the confirmation: leg, drive, what is written, what is replaced."""
        verb = "restore" if self.action == "rollback" else "write"
        lines = [
            f"leg {self.leg}: drive {self.drive}" + (f" at {self.drive_url}" if self.drive_url else ""),
            f"  {verb}:    {describe_table(self.table)}",
            f"            sha256 {self.table_sha256}, into bank {self.target_bank} (inactive), then switch to it",
            f"  replaces: bank {self.active_bank}, {describe_table(self.backup)}, sha256 {_short(self.backup_sha256)}…",
        ]
        if self.table_sha256 == self.backup_sha256:
            lines.append("  note: the drive's active table already holds exactly this table")
        if not self.table_enabled:
            lines.append("  note: the drive does not apply its table (table_enable = 0); the table is stored but not applied")
        return lines


@dataclass(frozen=True)
class PushResult:
    """A completed push or rollback: `bank` is now active, `previous_bank` held the backup."""

    action: str
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


# -- push ----------------------------------------------------------------------------------------

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


def prepare_push(axis: ServoAxis, table: TableBank | LegTable, *, table_limits: TableLimits | None = None,
                 quantum_um: float = QUANTUM_UM, drive_url: str = "", source: dict[str, Any] | None = None) -> PushPlan:
    """Read the drive and check `table` for it; writes nothing. PushRefused if the axis moves,
    the drive cannot be read, or the table does not fit the drive (see `check_table`)."""
    bank_table = quantize(_as_bank(table), quantum_um)
    identity, active, current, enabled = _read_state(axis, "push")
    try:
        limits = axis.limits()
    except DriverError as exc:
        raise PushRefused(f"leg {axis.leg}: cannot read the drive's soft limits ({_message(exc)}).") from None
    check_table(bank_table, axis.leg, limits, table_limits)
    return PushPlan("push", axis.leg, identity, drive_url, bank_table, table_sha256(bank_table), active, 1 - active,
                    current, table_sha256(current), enabled, source)


def push_table(axis: ServoAxis, table: TableBank | LegTable | None = None, *, plan: PushPlan | None = None,
               audit: AuditLog | None = None, operator: str = "", drive_url: str = "",
               table_limits: TableLimits | None = None, quantum_um: float = QUANTUM_UM,
               source: dict[str, Any] | None = None) -> PushResult:
    """Push `table` (or a `plan` from `prepare_push`) to `axis` the safe way (module docstring).

    Every attempt is appended to `audit` (when given): "started" with the backup before any
    write, then "ok", "failed" or "refused". Raises PushRefused (nothing written) or PushFailed
    (the message says which table is active). Returns the PushResult on success.
    """
    if plan is None:
        if table is None:
            raise ValueError("push_table needs a table or a plan")
        try:
            plan = prepare_push(axis, table, table_limits=table_limits, quantum_um=quantum_um,
                                drive_url=drive_url, source=source)
        except PushRefused as exc:
            _log_refusal(audit, "push", axis, drive_url, operator, exc, source)
            raise
    return _apply(axis, plan, audit, operator)


# -- rollback ------------------------------------------------------------------------------------

def prepare_rollback(axis: ServoAxis, audit: AuditLog, *, drive_url: str = "") -> PushPlan:
    """What `rollback` would restore: the backup of the last successful push of this leg to this
    drive (by identity) in `audit`. Writes nothing. PushRefused when there is none, when the
    drive's active table is not the one that push wrote (changed since, or already rolled back),
    or when the backup is damaged."""
    identity, active, current, enabled = _read_state(axis, "rollback")
    leg = axis.leg
    current_sha = table_sha256(current)
    entries = audit.entries()
    push = None
    for i in range(len(entries) - 1, -1, -1):
        e = entries[i]
        if e.action == "push" and e.outcome == "ok" and e.leg == leg and e.drive == identity:
            push, push_at = e, i
            break
    if push is None:
        raise PushRefused(f"leg {leg}: the audit log {audit.path} has no successful push to drive {identity}; "
                          "there is nothing to roll back.")
    if push.table_sha256 != current_sha:
        for later in entries[push_at + 1:]:
            if (later.action == "rollback" and later.outcome == "ok" and later.leg == leg and later.drive == identity
                    and later.table_sha256 == current_sha):
                raise PushRefused(f"leg {leg}: already rolled back at {later.time_utc}: the active table is the one from "
                                  f"before the push of {push.time_utc}. To use the pushed table again, push it again.")
        raise PushRefused(f"leg {leg}: the drive's active table (sha256 {_short(current_sha)}…) is not the table the last "
                          f"push wrote ({_short(push.table_sha256)}…, {push.time_utc}): it was changed outside this audit "
                          f"log ({audit.path}), so its backup would not undo the right change.")
    restore = table_from_json(push.backup, where=f"{audit.path}, push of {push.time_utc}")
    return PushPlan("rollback", leg, identity, drive_url, restore, table_sha256(restore), active, 1 - active,
                    current, current_sha, enabled, push.source,
                    {"rolls_back": push.op_id or push.id, "push_time_utc": push.time_utc})


def rollback(axis: ServoAxis, audit: AuditLog, *, plan: PushPlan | None = None, operator: str = "",
             drive_url: str = "") -> PushResult:
    """Restore the table that was active before the last successful push of this leg to this
    drive (from `audit`), the same safe way as a push; appended to `audit` as "rollback"."""
    if plan is None:
        try:
            plan = prepare_rollback(axis, audit, drive_url=drive_url)
        except PushRefused as exc:
            _log_refusal(audit, "rollback", axis, drive_url, operator, exc, None)
            raise
    return _apply(axis, plan, audit, operator)


# -- the one safe path ---------------------------------------------------------------------------

def _log(audit: AuditLog | None, entry: AuditEntry) -> AuditEntry | None:
    return audit.append(entry) if audit is not None else None


def _log_refusal(audit: AuditLog | None, action: str, axis: ServoAxis, drive_url: str, operator: str,
                 exc: BaseException, source: dict[str, Any] | None) -> None:
    """Record a refused attempt; the drive's identity only if it answers (best effort: the
    refusal itself is what the caller reports)."""
    if audit is None:
        return
    try:
        identity = axis.identity()
    except Exception:
        identity = ""
    try:
        audit.append(AuditEntry(action, axis.leg, "refused", str(exc), identity, drive_url, operator, source=source))
    except AuditError:
        pass


def _apply(axis: ServoAxis, plan: PushPlan, audit: AuditLog | None, operator: str) -> PushResult:
    leg, bank, prev = plan.leg, plan.target_bank, plan.active_bank
    op_id = new_id()
    base = dict(action=plan.action, leg=leg, drive=plan.drive, drive_url=plan.drive_url, operator=operator,
                table_sha256=plan.table_sha256, bank=bank, previous_bank=prev, source=plan.source,
                details=dict(plan.details), op_id=op_id)
    backup = table_to_json(plan.backup, prev)
    verb = "rollback" if plan.action == "rollback" else "push"
    try:
        _log(audit, AuditEntry(outcome="started", message=f"{verb} to bank {bank} started; backup of bank {prev} recorded",
                               backup=backup, **base))
    except AuditError as exc:
        raise PushRefused(f"leg {leg}: {exc}; the {verb} was not started.") from None

    def refuse(text: str) -> PushRefused:
        exc = PushRefused(text)
        try:
            _log(audit, AuditEntry(outcome="refused", message=str(exc), backup=backup, **base))
        except AuditError:
            pass  # the refusal is what matters; nothing was written to the drive
        return exc

    # the drive may have changed since the plan was made (another station, the drive panel)
    try:
        identity, active, current, _ = _read_state(axis, verb)
    except PushRefused as exc:
        raise refuse(str(exc.args[0])) from None
    if identity != plan.drive or active != prev or table_sha256(current) != plan.backup_sha256:
        raise refuse(f"leg {leg}: the drive changed since its table was read (active bank {active}, was {prev}); "
                     f"read it again and retry.")

    def fail(stage: str, exc: BaseException, state: str) -> PushFailed:
        text = f"leg {leg}: {verb} to drive {plan.drive} failed while {stage}: {_message(exc)}. {state}"
        try:
            _log(audit, AuditEntry(outcome="failed", message=text, backup=backup, **base))
        except AuditError as aexc:
            text += f" (The failure could not be logged: {aexc})"
        return PushFailed(text)

    stage = f"writing bank {bank}"
    try:
        axis.write_table(bank, plan.table)
        stage = f"reading bank {bank} back"
        back = axis.read_table(bank)
        if table_sha256(back) != plan.table_sha256:
            raise TableError(f"bank {bank} reads back as a different table (sha256 {_short(table_sha256(back))}…, "
                             f"expected {_short(plan.table_sha256)}…)")
    except DriverError as exc:
        raise fail(stage, exc, f"The previous table (bank {prev}, sha256 {_short(plan.backup_sha256)}…) is still "
                               "active: the drive only switches tables on the activation, which was not sent.") from None
    note = ""
    try:
        axis.activate_table(bank)
    except TableError as exc:  # the drive answered with a refusal: nothing switched
        raise fail(f"activating bank {bank}", exc,
                   f"The drive refused the switch: the previous table (bank {prev}) is still active.") from None
    except DriverError as exc:  # no answer: find out whether the switch landed
        state, text = _state_after_activation(axis, bank, prev, plan.table_sha256)
        if state != "new":
            raise fail(f"activating bank {bank}", exc, text) from None
        note = f" (the activation request got no answer, but the drive then reported bank {bank} active)"
    else:
        state, text = _state_after_activation(axis, bank, prev, plan.table_sha256)
        if state != "new":
            raise fail("confirming the switch", TableError(f"the drive accepted the switch to bank {bank}"), text) from None
    text = f"{verb} ok: bank {bank} active on leg {leg} ({describe_table(plan.table)}){note}"
    try:
        _log(audit, AuditEntry(outcome="ok", message=text, backup=backup, **base))
    except AuditError as exc:
        raise PushFailed(f"leg {leg}: the table was written and bank {bank} is active, but the audit log could not "
                         f"record it ({exc}); its backup is in the 'started' entry ({op_id}).") from None
    return PushResult(plan.action, leg, plan.drive, bank, prev, plan.table_sha256, plan.backup_sha256,
                      plan.table.point_count, plan.table_enabled, op_id)


def _state_after_activation(axis: ServoAxis, bank: int, prev: int, sha: str) -> tuple[str, str]:
    """After an activation request: ("new" | "previous" | "unknown", sentence for the error)."""
    try:
        now = axis.active_bank()
        if now == bank and table_sha256(axis.read_table(bank)) == sha:
            return "new", ""
    except DriverError:
        return "unknown", (f"It is NOT known whether the drive switched: it stopped answering. Before moving the axis, "
                           f"read its active bank (register active_bank, docs/register-map.md): {prev} = the previous "
                           f"table, {bank} = the new one.")
    if now == prev:
        return "previous", f"The drive reports bank {prev} active: the previous table is still active."
    return "unknown", (f"The drive reports bank {now} active but it does not hold the table written; do not use the "
                       "axis before checking its table.")
