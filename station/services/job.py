"""The one shape of every job the station runs (issue 32 part 1), for every front end alike:

    request (plain data the front end fills)  ->  prepare(request, cfg)  ->  Prepared | InputError
    Prepared.run(sinks, control)  ->  JobOutcome

- `prepare` makes every refusal, output check and size estimate before anything moves or is
  written: it raises `InputError` (one line naming what was wrong and what to do) or returns a
  `Prepared` that says what it will do (`lines`) and what it still asks (`question`: a yes/no the
  front end puts to the user, e.g. a sweep of a compensated leg; None = nothing to ask).
- `JobRunner` runs a prepared job: it owns the rig lock (one rig job at a time in this process,
  and the drive lock across processes), the abort (`RunControl`), and the follow-ups every job
  has (a line when its records wait in the catalog's outbox). The CLI, the TUI and the web only
  fill requests and present the events and the outcome.

Nothing here imports the procedures' heavy modules: a request and its refusal load nothing
beyond the standard library (`station X --help` and an argument error start at once).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Protocol

from procedures.vocabulary import InputError


@dataclass
class JobOutcome:
    """What a job ended with. `status`: "completed", "aborted", "failed" (the values of
    procedures.vocabulary.Outcome) or "done" for a job that is not a run of the rig (a fit, a
    table, a report). `outputs`: the files it wrote. `lines`: what to tell the user, in order.
    `data`: the job's own result (a RunResult, a fitted model, ...) for the front end to present."""

    status: str
    outputs: list[Path] = field(default_factory=list)
    lines: list[str] = field(default_factory=list)
    data: Any = None

    @property
    def ok(self) -> bool:
        return self.status in ("completed", "done")


class Prepared(Protocol):
    """A job that passed every check: `run` does it."""

    needs_rig: bool  # True: the job moves or writes to the drives (JobRunner takes the rig lock)
    question: str | None  # a yes/no to confirm before run (None: nothing to ask)
    lines: list[str]  # what it will do, for the user to read before it starts

    def run(self, sinks: Iterable[Any] = (), control: Any = None) -> JobOutcome: ...


class RigBusy(InputError):
    """Another job holds the rig in this process (nothing was done)."""


class JobRunner:
    """Runs prepared jobs one rig job at a time (jobs that do not touch the rig run beside them).

    `on_outcome(outcome)`: the follow-ups every front end gets the same way (each is called
    after the job, whatever its status)."""

    def __init__(self, follow_ups: Iterable[Callable[[JobOutcome], None]] = ()) -> None:
        self._rig = threading.Lock()
        self._follow_ups = list(follow_ups)
        self.control: Any = None  # the running rig job's RunControl (abort() reaches it)

    @property
    def busy(self) -> bool:
        return self._rig.locked()

    def run(self, job: Prepared, sinks: Iterable[Any] = (), control: Any = None,
            confirmed: bool = False) -> JobOutcome:
        """Run `job`. A job with a `question` runs only `confirmed` (the front end asked); refused
        otherwise with the question's text. RigBusy when another rig job is running."""
        if job.question and not confirmed:
            raise InputError(job.question)
        if not job.needs_rig:
            return self._follow(job.run(sinks, control))
        if not self._rig.acquire(blocking=False):
            raise RigBusy("the rig is busy with another job; wait for it to finish, or abort it")
        try:
            if control is None:
                from procedures.engine.control import RunControl

                control = RunControl()
            self.control = control
            return self._follow(job.run(sinks, control))
        finally:
            self.control = None
            self._rig.release()

    def abort(self) -> bool:
        """Abort the running rig job (its drives quick-stop from this thread). False: none runs."""
        control = self.control
        if control is None:
            return False
        control.abort()
        return True

    def _follow(self, outcome: JobOutcome) -> JobOutcome:
        for follow in self._follow_ups:
            follow(outcome)
        return outcome
