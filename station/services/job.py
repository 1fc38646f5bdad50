"""The one shape of every job the station runs (issue 32 part 1), for every front end alike:

    request (plain data the front end fills)  ->  prepare(request, cfg)  ->  Prepared | InputError
    JobRunner.run(prepared, sinks, confirm)  ->  JobOutcome

- `prepare` makes every refusal, output check and size estimate before anything moves or is
  written: it raises `InputError` (one line naming what was wrong and what to do) or returns a
  `Prepared` that says what it will do (`lines`) and what it still asks (`question`: a yes/no the
  front end puts to the user; None = nothing to ask).
- A rig job's checks that need the devices (which legs have a drive, which tables are active) are
  its `check()`, which the runner calls holding the rig lock, before the question and before
  anything moves: it refuses (InputError) or sets `question` (e.g. a sweep of a compensated leg,
  `declined` the refusal when the answer is no).
- `JobRunner` runs prepared jobs: it owns the rig lock (one rig job at a time; the lock the front
  end's rig actions share), the run numbering (`claim`), the abort (the job's `RunControl`) and
  the follow-ups every job has. The CLI, the TUI and the web only fill requests and present the
  events and the outcome.

Nothing here imports the procedures' heavy modules: a request and its refusal load nothing
beyond the standard library (`station X --help` and an argument error start at once).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable, Mapping, Protocol

from procedures.vocabulary import InputError

if TYPE_CHECKING:  # annotations only: a request and its refusal load nothing of the procedures
    from procedures.compensation.push import OperationFinished
    from procedures.engine.control import RunControl
    from procedures.engine.runner import RunResult, Sink
    from station.services.config import StationConfig

FAILED = "failed"


@dataclass
class JobOutcome:
    """What a job ended with, whatever the job.

    `status`: a sweep's "completed" / "aborted" / "failed" (procedures.vocabulary.Outcome), a
    table operation's "ok" / "refused" / "cancelled" / "failed" / "completed"
    (procedures.vocabulary.Outcome), or "done" for a job that is not a run of the rig (a
    fit, a table, a report). `outputs`: the files it wrote. `lines`: what to tell the user, in
    order. `data`: the job's own result for the front end to present (a fitted model, ...).

    A job run through the procedures' runner also carries the runner's `run` (its RunResult:
    outcome and points), every `events` it yielded, the `finished` event of a table operation
    (procedures.compensation.push.OperationFinished; None when the run broke off), the audit
    entries that could not be stored (`audit_problems`), whether a push was refused for values
    that look like a unit slip (`implausible`: the user may accept them) and the lines of the
    implausible values the user accepted (`warnings`)."""

    status: str
    outputs: list[Path] = field(default_factory=list)
    lines: list[str] = field(default_factory=list)
    data: Any = None
    run: RunResult | None = None
    events: list = field(default_factory=list)
    finished: OperationFinished | None = None
    audit_problems: list[str] = field(default_factory=list)
    implausible: bool = False
    warnings: list[str] = field(default_factory=list)

    @property
    def outcome(self) -> str:
        return self.status

    @property
    def ok(self) -> bool:
        return self.status in ("completed", "done", "ok")

    @property
    def points(self) -> int:
        """The points the run measured (0 for a job that measured none)."""
        return int(getattr(self.run, "points", 0) or 0)

    def of(self, kind: type) -> list:
        """The events of `kind` the job yielded, in order."""
        return [e for e in self.events if isinstance(e, kind)]


@dataclass(kw_only=True)
class OfflineJob:
    """What every prepared job that does not touch the rig has of `Prepared`: no rig lock,
    nothing to ask; `lines` what it will do (a keyword of the job's constructor)."""

    needs_rig: bool = False
    question: str | None = None
    lines: list[str] = field(default_factory=list)


class Prepared(Protocol):
    """A job that passed every check it can make without the devices: `run` does it.

    Optional: `check()`, the checks that read the devices (called by the runner under the rig
    lock, before anything moves; it raises InputError or sets `question`), and `declined`, the
    refusal when the question is answered no."""

    needs_rig: bool  # True: the job moves or writes to the drives (JobRunner takes the rig lock)
    question: str | None  # a yes/no to confirm before run (None: nothing to ask)
    lines: list[str]  # what it will do, for the user to read before it starts

    def run(self, sinks: Iterable[Sink] = (), control: RunControl | None = None) -> JobOutcome: ...


def config_or_load(cfg: StationConfig | None, path: str | Path | None = None) -> StationConfig:
    """`cfg` when the front end holds one, else the station config `path` names (None: where
    station.services.config.load_config looks), loaded only then."""
    if cfg is not None:
        return cfg
    from station.services.config import load_config

    return load_config(path)


def require_legs(axes: Mapping[int, object] | None, legs: Iterable[int], device: str = "the rig",
                 nothing: str = "nothing moved") -> None:
    """A rig job's first device check: connected (`axes` not None) with a drive for every leg of
    `legs`; InputError naming the missing legs and what was not done (`nothing`) otherwise."""
    if axes is None:
        raise InputError(f"not connected to {device}; {nothing}")
    missing = [leg for leg in legs if leg not in axes]
    if missing:
        raise InputError(f"no drive connected for leg(s) {missing} (connected: {sorted(axes)}); {nothing}")


class RigBusy(InputError):
    """Another job holds the rig (nothing was done)."""


class NotConfirmed(InputError):
    """The job's question was answered no, or nobody could answer it (nothing moved)."""


Confirm = Callable[[str], bool]
"""`confirm(question) -> bool`: how a front end asks a job's question (a terminal prompt, a dialog)."""


@dataclass
class Ticket:
    """A job claimed on the runner: its run number (the front end's events carry it) and its
    `control` (pause, resume, abort). Claimed on the front end's thread, run on a worker."""

    run: int
    control: RunControl
    rig: bool = True  # the job holds the rig: no other rig job is claimed while it lives


class JobRunner:
    """Runs prepared jobs, one rig job at a time (jobs that do not touch the rig run beside them).

    `lock`: the rig lock the front end's rig actions and status polls share (None: one of the
    runner's own); a rig job waits for it `wait_s` (a rig action finishing), else RigBusy.
    `follow_ups`: called with every outcome, whatever its status (the same for every front end)."""

    BUSY = "the rig is busy with another job; wait for it to finish, or abort it; nothing was done"

    def __init__(self, follow_ups: Iterable[Callable[[JobOutcome], None]] = (), lock: threading.Lock | None = None,
                 wait_s: float = 0.0) -> None:
        self._rig = lock if lock is not None else threading.Lock()
        self._wait_s = wait_s
        self._follow_ups = list(follow_ups)
        self._claims = threading.Lock()
        self._claimed: Ticket | None = None  # the rig job claimed and not yet ended
        self.runs = 0  # the jobs numbered so far

    @property
    def busy(self) -> bool:
        return self._claimed is not None

    @property
    def control(self) -> RunControl | None:
        """The claimed rig job's RunControl (None: none)."""
        ticket = self._claimed
        return ticket.control if ticket is not None else None

    def claim(self, rig: bool = True) -> Ticket:
        """Number a new job and make its run control; with `rig`, RigBusy while another rig job
        is claimed (before any worker starts: the front end says so at once)."""
        from procedures.engine.control import RunControl

        with self._claims:
            if rig and self._claimed is not None:
                raise RigBusy(self.BUSY)
            self.runs += 1
            ticket = Ticket(self.runs, RunControl(), rig)
            if rig:
                self._claimed = ticket
            return ticket

    def release(self, ticket: Ticket) -> None:
        """End `ticket`'s claim (run() does it; a front end whose job never ran does it itself)."""
        with self._claims:
            if self._claimed is ticket:
                self._claimed = None

    def run(self, job: Prepared, sinks: Iterable[Sink] = (), control: RunControl | None = None, confirmed: bool = False,
            confirm: Confirm | None = None, ticket: Ticket | None = None) -> JobOutcome:
        """Run `job` (its claim `ticket`, or a new one). A rig job takes the rig lock, then makes
        its device checks (`check()`); a job with a `question` runs only when `confirmed` or
        `confirm(question)` says yes, else NotConfirmed with its `declined` text (nothing moved).
        RigBusy when another rig job holds the rig."""
        if not job.needs_rig:
            try:
                self._ask(job, confirmed, confirm, None)
                return self._follow(job.run(sinks, control))
            finally:
                if ticket is not None:
                    self.release(ticket)
        if ticket is None:
            ticket = self.claim()
            if control is not None:
                ticket.control = control
        try:
            taken = self._rig.acquire(timeout=self._wait_s) if self._wait_s > 0 else self._rig.acquire(blocking=False)
            if not taken:  # a rig action still running after `wait_s`
                raise RigBusy(self.BUSY)
            try:
                check = getattr(job, "check", None)
                if check is not None:
                    check()
                self._ask(job, confirmed, confirm, ticket.control)
                return self._follow(job.run(sinks, ticket.control))
            finally:
                self._rig.release()
        finally:
            self.release(ticket)

    def abort(self, reason: str = "aborted by the operator") -> bool:
        """Abort the running rig job (its drives quick-stop from this thread). False: none runs."""
        control = self.control
        if control is None:
            return False
        control.abort(reason)
        return True

    @staticmethod
    def _ask(job: Prepared, confirmed: bool, confirm: Confirm | None, control: RunControl | None) -> None:
        question = getattr(job, "question", None)
        if not question or confirmed:
            return
        yes = confirm is not None and confirm(question)
        if control is not None and control.aborted:
            yes = False  # aborted while the question was open (e.g. the UI quit)
        if not yes:
            raise NotConfirmed(getattr(job, "declined", "") or f"not confirmed: {question}")

    def _follow(self, outcome: JobOutcome) -> JobOutcome:
        for follow in self._follow_ups:
            follow(outcome)
        return outcome
