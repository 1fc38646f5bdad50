"""The Compensation page's controller: reads the drives' tables and runs push, rollback and
verify through station.services.table_jobs (the same jobs and procedures as the command line), in
worker threads. It asks for confirmation with a dialog on the UI thread and posts the outcome
back as messages; it never touches a widget from a worker.
"""

from __future__ import annotations

import threading
from typing import Any, Protocol

from textual.message import Message

from station.services.config import StationConfig
from station.services.push_jobs import PUSH, ROLLBACK, PushRequest, RollbackRequest, outcome_lines, plan_lines, \
    prepare_push, prepare_rollback
from station.tui.error_text import describe
from station.tui.messages import Notice
from station.tui.screens.common import ConfirmScreen
from station.tui.screens.compensation_widgets import DriveTable
from station.tui.state import SweepState


class StationHost(Protocol):
    """What the controller uses of the app (station.tui.app.StationApp is one): stated here, not
    imported, because the app imports the compensation page that holds this controller."""

    cfg: StationConfig
    sweep: SweepState
    hide_volatile: bool

    @property
    def rig(self): ...  # station.services.wiring.Rig once connected, else None (as the app's)

    @property
    def rig_lock(self) -> threading.Lock: ...

    def post_message(self, message: Message) -> bool: ...

    @property
    def jobs(self): ...  # station.services.job.JobRunner: the app's one runner of rig jobs

    def start_job(self, job, label: str = "sweep", on_done=None) -> bool: ...


UI_ACCEPT_HOW, UI_ACCEPTED_AS = "confirm it in the dialog that follows", "confirmed in the dialog"
"""How the page lets the user accept implausible values (the command line's --accept-implausible)."""

RIG_WAIT_S = 5.0
"""How long an action waits for the rig (a status poll, another action) before saying it is busy."""


class DriveTablesRead(Message):
    def __init__(self, tables: dict[int, DriveTable]) -> None:
        super().__init__()
        self.tables = tables


class TableJobDone(Message):
    """A push or rollback ended, whichever way (`job`: station.services.table_jobs.JobOutcome, with
    `lines` how it ended in the words of every front end, station.services.push_jobs.outcome_lines;
    or None with `error` when it could not run). `accept_again`: for a push refused for implausible
    values, the same push with them accepted (started only after the user confirms it)."""

    def __init__(self, action: str, leg: int | None, job: Any = None, error: str = "", accept_again=None,
                 lines: list[str] | None = None) -> None:
        super().__init__()
        self.action = action
        self.leg = leg
        self.job = job
        self.error = error
        self.accept_again = accept_again
        self.lines = list(lines or [])


class VerificationDone(Message):
    def __init__(self, leg: int, job: Any) -> None:
        super().__init__()
        self.leg = leg
        self.job = job


class CompensationController:
    """Runs the page's jobs for `screen` (a Textual screen: workers and messages go through it)."""

    def __init__(self, screen) -> None:
        self.screen = screen

    @property
    def app(self) -> StationHost:
        return self.screen.app

    def audit(self):
        """The audit log `station push/rollback/verify` use: <recordings_dir>/audit.jsonl."""
        from station.services.session_identity import station_audit_log

        return station_audit_log(self.app.cfg)

    def refusal(self, what: str) -> str:
        """Why the rig cannot take `what` now ("" = it can)."""
        if self.app.rig is None:
            return "Not connected to the rig: connect on the Rig screen (F1)."
        if self.app.sweep.active:
            return f"A sweep is running: {what.lower()} only when it has ended."
        return ""

    # -- reading the drives ----------------------------------------------------------------------------
    def read_drives(self, legs: list[int]) -> None:
        rig, lock = self.app.rig, self.app.rig_lock  # read on the UI thread, the rig's only owner
        self.screen.run_worker(lambda: self._read_drives(rig, lock, legs), thread=True, exclusive=True,
                               group="drive-tables", exit_on_error=False)

    def _read_drives(self, rig, lock, legs: list[int]) -> None:
        if rig is None or not lock.acquire(timeout=RIG_WAIT_S):
            return
        out: dict[int, DriveTable] = {}
        try:
            for leg in legs:
                dt = DriveTable(leg)
                axis = rig.axes.get(leg)
                if axis is None:
                    dt.error = "no drive connected for this leg"
                else:
                    try:
                        dt.target = str(getattr(axis, "compensation_target", "drive"))
                        dt.identity = axis.identity()
                        dt.active_bank = axis.active_bank()
                        dt.table = axis.read_table(dt.active_bank)
                    except Exception as exc:
                        dt.error = describe(exc)
                out[leg] = dt
        finally:
            lock.release()
        self.screen.post_message(DriveTablesRead(out))

    # -- push and rollback ---------------------------------------------------------------------------
    def push(self, leg: int, table, source: dict | None, table_name: str | None = None,
             accept_implausible: bool = False) -> None:
        """Push `table` (a procedures.compensation.table.LegTable) to `leg`'s drive after a confirmation
        (the job of `station push`, station/services/push_jobs.py); values that look like a unit slip
        are refused unless `accept_implausible` (`table_name` names it; default: the source's path)."""
        request = PushRequest(legs=(leg,), tables={leg: table}, sources={leg: source}, table_name=table_name,
                              accept_implausible=accept_implausible, accept_how=UI_ACCEPT_HOW,
                              accepted_as=UI_ACCEPTED_AS)
        self._table_job(PUSH, leg, request, self.confirm,
                        again=lambda: self.push(leg, table, source, table_name, accept_implausible=True))

    def push_all(self, tables: dict, sources: dict[int, dict], table_name: str | None = None,
                 accept_implausible: bool = False) -> None:
        """Push every leg's table after one confirmation."""
        request = PushRequest(legs=tuple(sorted(tables)), tables=tables, sources=sources, table_name=table_name,
                              accept_implausible=accept_implausible, accept_how=UI_ACCEPT_HOW,
                              accepted_as=UI_ACCEPTED_AS)
        self._table_job(PUSH, None, request, self.confirm_all,
                        again=lambda: self.push_all(tables, sources, table_name, accept_implausible=True))

    def rollback(self, leg: int) -> None:
        self._table_job(ROLLBACK, leg, RollbackRequest(leg=leg), self.confirm)

    def _table_job(self, action: str, leg: int | None, request, confirm, again=None) -> None:
        """Prepare and run the push or rollback `request` asks for in a worker, through the app's
        JobRunner (the rig lock, one rig job at a time) on the connected rig, confirmed by
        `confirm`; `again`: the job with implausible values accepted, offered when they refused it."""
        rig, cfg, jobs = self.app.rig, self.app.cfg, self.app.jobs  # read on the UI thread

        def work() -> None:
            from station.services.wiring import drive_url_of

            try:
                job = (prepare_push if action == PUSH else prepare_rollback)(request, cfg)
                if job.needs_rig:
                    if rig is None:
                        self.screen.post_message(TableJobDone(action, leg, error="Not connected to the rig."))
                        return
                    job.axes, job.drive_url, job.confirm_plans = dict(rig.axes), drive_url_of(cfg), confirm
                ended = jobs.run(job)
            except Exception as exc:  # busy, a leg without a drive, an audit log that cannot be written: said
                self.screen.post_message(TableJobDone(action, leg, error=describe(exc, f"{action} of leg {leg}")))
                return
            self.screen.post_message(TableJobDone(action, leg, ended, accept_again=again if ended.implausible else None,
                                                  lines=outcome_lines(ended, cfg, job.audit)))

        self.screen.run_worker(work, thread=True, exclusive=True, group="push", exit_on_error=False)

    def confirm(self, plan) -> bool:
        """The procedures' `Confirm` of one plan (procedures.compensation.push.PushPlan), called on
        the worker thread: a dialog on the UI thread, waited for. False (cancelled) if the app
        closes meanwhile."""
        lines = plan_lines(plan, drive_url=not self.app.hide_volatile)
        verb = "Push this table to" if plan.action == PUSH else "Roll back the table of"
        holder = "The station's" if plan.target == "station" else "The drive's"
        question = (f"[b]{verb} leg {plan.leg}[/b], drive [b]{plan.drive}[/b], compensation target "
                    f"[b]{plan.target}[/b]?\n\n" + "\n".join(lines)
                    + f"\n\n{holder} current table is backed up in the audit log first; on any failure it stays active.")
        return self._ask(question, "Push" if plan.action == PUSH else "Roll back")

    def _ask(self, question: str, yes: str) -> bool:
        """A dialog on the UI thread, waited for from the worker; False if the app closes meanwhile."""
        answer: dict[str, bool] = {}
        done = threading.Event()

        def answered(yes: bool | None) -> None:
            answer["yes"] = bool(yes)
            done.set()

        try:
            app = self.app

            def ask() -> None:
                app.push_screen(ConfirmScreen(question, yes=yes, no="Cancel"), answered)

            app.call_from_thread(ask)
        except Exception:  # the app is closing: nobody can answer, so nothing is written (cancelled)
            return False
        while not done.wait(0.2):
            if not app.is_running:
                return False
        return answer["yes"]

    def confirm_all(self, plans: list) -> bool:
        """One dialog for several legs' plans (a whole platform)."""
        lines = []
        for plan in plans:
            lines.extend(plan_lines(plan, drive_url=False, checksums=False))
        question = (f"[b]Push the tables of legs {', '.join(str(p.leg) for p in plans)}[/b]?\n\n" + "\n".join(lines)
                    + "\n\nEach drive's current table is backed up in the audit log first; a leg that fails keeps its "
                    "table and stops the rest.")
        return self._ask(question, "Push all")

    def notice(self, message: TableJobDone) -> tuple[str, str]:
        """(text, severity) for how a push or rollback ended: the service's lines (the words `station
        push` and `station rollback` print), then what this page adds: the audit log's problems
        and the implausible values the user accepted."""
        if message.error:
            return message.error, "error"
        job = message.job
        problems = "".join(f" (audit log: {p})" for p in job.audit_problems)
        problems += "".join(f"\n{w}" for w in job.warnings)  # implausible values the user accepted
        end = job.finished
        severity = "information" if end is not None and end.outcome in ("ok", "cancelled") else "error"
        return "\n".join(message.lines) + problems, severity

    # -- verify ----------------------------------------------------------------------------------------
    def verify(self, leg: int, analysis) -> bool:
        """A verification sweep of `leg` with its table active, repeating the plan of the
        calibration on show (`analysis.session`): the job `station verify --before` runs
        (station/services/verify_job.py), shown on the Sweep page. False (and a notice) when it
        cannot start."""
        from station.services.sessions import default_session_path
        from station.services.verify_job import VerifyRequest, prepare_verify

        made = default_session_path(self.app.cfg, (leg,))  # runs/ui-STAMP-legN.h5
        out = made.with_name("verify-" + made.name.removeprefix("ui-"))
        try:
            job = prepare_verify(VerifyRequest(legs=(leg,), out=out, before=analysis.session.path, make_parents=True),
                                 self.app.cfg)
        except Exception as exc:
            self.app.post_message(Notice(describe(exc, "cannot verify"), "error", "Verify"))
            return False
        job.rig = self.app.rig
        return self.app.start_job(job, label=f"verification of leg {leg}",
                                  on_done=lambda state: self.screen.post_message(VerificationDone(leg, state.result)))
