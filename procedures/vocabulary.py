"""The words every layer may name: the errors for bad input and how an operation ended.

Procedures, services and front ends all raise or catch `InputError` and compare an
`Outcome`; keeping both here, in a module that imports nothing, lets any of them name these words
without depending on the engine or on a domain (tests/test_layering.py: SHARED_VOCABULARY).
"""

from __future__ import annotations

from enum import StrEnum


class InputError(ValueError):
    """Bad input (file, row, field). The message names what was wrong, where, and what to do; it
    is shown to the user as is, without traceback."""


class SchemaError(InputError):
    """A recording or model file does not follow a schema this version understands."""


class PlanError(InputError):
    """A sweep plan is invalid, e.g. targets outside the drive's soft limits."""


class Outcome(StrEnum):
    """How an operation ended, or that it has not ended yet.

    A run (sweep, verification, replay) ends COMPLETED, ABORTED or FAILED (`written()`): the
    `outcome` attribute of a session file, INCOMPLETE when read from a file never finished. A
    push or rollback logs STARTED in the audit log (with the backup), then OK, FAILED, REFUSED or
    CANCELLED (procedures.compensation.audit.FINAL_PUSH_OUTCOMES); a verification logs REFUSED, or its sweep's outcome.

    The values are the strings written to HDF5 and JSON (unchanged since before this enum), and
    `StrEnum` members compare equal to them, so old files read the same.
    """

    COMPLETED = "completed"   # every planned point measured
    ABORTED = "aborted"       # stopped by the operator (abort, Ctrl-C): the drives were stopped
    FAILED = "failed"         # stopped by an error (retries exhausted, a device gone, a failed write)
    INCOMPLETE = "incomplete"  # read only: a session file that was never finished (a crash)
    STARTED = "started"       # audit: a push or rollback began (its entry carries the backup)
    OK = "ok"                 # audit: a push or rollback done, the new table active
    REFUSED = "refused"       # audit: refused before anything was written to a drive
    CANCELLED = "cancelled"   # audit: the operator said no; nothing was written

    @classmethod
    def written(cls) -> tuple["Outcome", ...]:
        """The outcomes a finished session file can hold."""
        return (cls.COMPLETED, cls.ABORTED, cls.FAILED)

