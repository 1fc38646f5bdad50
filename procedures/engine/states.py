"""Outcomes and actions as enums, shared by the runner, the session writer, the audit log and
the front ends. Values are the strings written to HDF5 and JSON (unchanged from before these
enums), and `StrEnum` members compare equal to them, so old files read the same.
"""

from __future__ import annotations

from enum import StrEnum

from drivers.interfaces import DriveState, FaultKind  # noqa: F401  (re-exported: one import for procedures' users)


class Outcome(StrEnum):
    """How a run (sweep, verification, replay) ended; the `outcome` attribute of a session file."""

    COMPLETED = "completed"   # every planned point measured
    ABORTED = "aborted"       # stopped by the operator (abort, Ctrl-C): the drives were stopped
    FAILED = "failed"         # stopped by an error (retries exhausted, a device gone, a recorder failure)
    INCOMPLETE = "incomplete"  # read only: a session file that was never finished (a crash)

    @classmethod
    def written(cls) -> tuple["Outcome", ...]:
        """The outcomes a finished session file can hold."""
        return (cls.COMPLETED, cls.ABORTED, cls.FAILED)


class Action(StrEnum):
    """What an audit log entry records."""

    PUSH = "push"
    ROLLBACK = "rollback"
    VERIFY = "verify"
    APPROVE = "approve"  # a calibration certificate approved (station certificate approve)


class AuditOutcome(StrEnum):
    """The `outcome` of an audit entry. A push or rollback logs STARTED (with the backup), then
    one of OK / FAILED / REFUSED / CANCELLED; a verification logs REFUSED, or the outcome of
    its sweep (COMPLETED / ABORTED / FAILED)."""

    STARTED = "started"
    OK = "ok"
    FAILED = "failed"
    REFUSED = "refused"
    CANCELLED = "cancelled"
    COMPLETED = "completed"
    ABORTED = "aborted"
