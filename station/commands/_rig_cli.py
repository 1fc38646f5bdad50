"""How a command runs a prepared rig job (`station run`, `station sweep`): one place for the
connect, the Ctrl-C handler and the run through the JobRunner (rig lock, run control, abort).
Command-line only; the job is the service's (station.services.sweep_job). (Not a command: cli.py
skips "_" modules.)"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from station.services.job import Confirm, JobOutcome


def run_on_rig(job: Any, confirm: "Confirm | None" = None, **connect: Any) -> "tuple[JobOutcome, Any]":
    """Connect the rig `job` names (`connect`: job.connect's options), say which, and run `job`
    through a JobRunner with a progress bar; Ctrl-C aborts it (the drives stop, the recording is
    closed as aborted; station.interrupt.abort_on_sigint). Returns the outcome and the job's
    RunControl (its `reason` says whether Ctrl-C aborted it). A second Ctrl-C raises
    KeyboardInterrupt once the runner has finished the session as aborted."""
    from station.interrupt import abort_on_sigint
    from station.progress import ConsoleProgress
    from station.services.job import JobRunner

    runner = JobRunner()
    ticket = runner.claim()
    with job.connect(**connect) as rig:
        print(f"rig: {rig.description}")
        with abort_on_sigint(ticket.control) as control:
            return runner.run(job, [ConsoleProgress()], confirm=confirm, ticket=ticket), control
