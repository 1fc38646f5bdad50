"""Starting the jobs on show (a sweep, a resumed sweep, a verification, a replay) through app.jobs, the JobRunner."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Callable

from textual import work

from procedures.vocabulary import InputError
from station.services.job import RigBusy, Ticket
from station.services.sessions import replay_output_path
from station.services.sweep_job import OutputExists, SweepRequest, prepare_sweep
from station.tui.bridge import SweepEnded, TuiBridge
from station.tui.error_text import describe
from station.tui.messages import ReplayRigOpened
from station.tui.screens.common import ConfirmScreen
from station.tui.state import LegTrace, SweepState

# The ways out of a refused sweep of a compensated leg, on this UI (station.services.jobs.compensated_refusal).
UI_WAYS_OUT = {"rollback": "b on the Compensation page, F4", "confirm": "answer yes when asked"}


class JobDispatch:
    """The app's part that starts jobs: it claims a ticket of `self.jobs` (the JobRunner, which
    owns the rig lock, run numbering and abort), makes a new SweepState the job on show and runs
    the job in a worker, which always ends with one SweepEnded (station.tui.job_events takes it
    in). Assigns `sweep`, `sweep_control`, `_runs` and clears `_sweep_idle` (StationApp.__init__),
    on the app's thread only. Uses of the app: `cfg`, `rig`, `session`, `notify`, `push_screen`,
    `call_from_thread`, `_sweep_changed` (station.tui.redraws)."""

    def sweep_refusal(self) -> str:
        """'' when no job holds the rig; else the sentence a refused rig action shows: what the
        job is doing and the way out (a paused sweep still holds the rig)."""
        s = self.sweep
        if not s.active:
            return ""
        if s.status == "paused":
            return (f"The {s.label} is paused, and a paused {s.label} still holds the rig: abort it (a), or resume "
                    "it (p) and let it finish, first (Sweep page, F2).")
        if s.status == "aborting":
            return f"The {s.label} is being aborted: wait until the drives have stopped (Sweep page, F2)."
        return f"A {s.label} is running: abort it first (a on the Sweep page, F2)."

    def start_sweep(self, request: SweepRequest, on_done: Callable[[SweepState], None] | None = None) -> bool:
        """Prepare the sweep `request` asks for (new, or resumed with `request.resume`) on the
        connected rig (station.services.sweep_job, the job `station sweep` runs) and start it.
        Refusals are notifications; True if it started. `on_done(state)`: as for start_job."""
        title = "Resume" if request.resume else "Sweep"
        if not self._rig_free(title):
            return False
        if request.ways_out is None:  # a refused compensated leg: the ways out on this UI
            request.ways_out = UI_WAYS_OUT
        try:
            job = prepare_sweep(request, self.cfg, rig=self.rig)
        except OutputExists as exc:
            self.notify(f"{exc.path} exists already; choose another file name.", title=title, severity="error")
            return False
        except Exception as exc:
            self.notify(describe(exc, "cannot resume" if request.resume else "cannot start the sweep"), title=title,
                        severity="error", timeout=15)
            return False
        return self.start_job(job, on_done=on_done)

    def resume_sweep(self, path: Path) -> bool:
        """Finish the aborted (or failed) session `path`: its own plan, appended to the same
        file, by the job `station sweep --resume` runs. Refusals (a complete or imported file, a
        sweep running, no rig) are notifications; True if it started."""
        return self.start_sweep(SweepRequest(out=Path(path).expanduser(), resume=True))

    def _rig_free(self, title: str) -> bool:
        """True when a job may take the rig now; else says why (a job running, no rig, a move)."""
        if self.sweep.active:
            self.notify(self.sweep_refusal(), title=title, severity="warning")
            return False
        what, refusal = self.session.job_refusal()
        if what == "rig":
            self.notify(f"{refusal}: go to the Rig screen (F1) and press c to connect.", title=title,
                        severity="error", timeout=10)
            return False
        if refusal:
            self.notify(f"{refusal}: wait for it, or stop it (x on the Rig page, F1), first.", title=title,
                        severity="warning", timeout=10)
            return False
        return True

    def start_job(self, job, label: str = "sweep", on_done: Callable[[SweepState], None] | None = None) -> bool:
        """Start the prepared rig job `job` (a PreparedSweep, a verification: station/services/job.py)
        through the app's JobRunner, shown on the Sweep page. `label` names it on screen ("sweep",
        "verification of leg 2"); `on_done(state)` is called on the app's thread when it has ended
        (whatever the outcome), with its JobOutcome in `state.result`."""
        if not self._rig_free(label.capitalize()):
            return False
        try:
            ticket = self.jobs.claim()
        except RigBusy as exc:
            self.notify(str(exc), title=label.capitalize(), severity="warning")
            return False
        state = SweepState(out=job.out, legs=job.legs, plan_kind=job.kind, status="starting", total=job.total_points,
                           label=label)
        if getattr(job, "recorded", None) is not None:
            _show_recorded_points(state, job.recorded)
        self._begin_run(ticket, state, on_done)
        self._job_worker(ticket, job, self._sweep_idle)
        return True

    def _begin_run(self, ticket: Ticket, state: SweepState, on_done: Callable[[SweepState], None] | None) -> None:
        """Make `state` the job on show, with `ticket`'s run number and run control."""
        self._runs[ticket.run] = (state, on_done)
        self.sweep = state
        self.sweep_control = ticket.control
        self._sweep_idle.clear()
        self._sweep_changed()

    @work(thread=True, group="sweep", exit_on_error=False)
    def _job_worker(self, ticket: Ticket, job, idle: threading.Event) -> None:
        """Run `job` through the JobRunner (the rig lock, the device checks, the question in a
        dialog, the run); always ends with one SweepEnded."""
        outcome, points, error, ended = "error", 0, "", None
        try:
            ended = self.jobs.run(job, [TuiBridge(self, ticket.run)], ticket=ticket,
                                  confirm=lambda question: self._ask_from_worker(question, ticket.control))
            outcome = ended.run.outcome if ended.run is not None else ended.status
            points = ended.points
            if ended.status == "refused" and ended.finished is not None:  # nothing moved: say why, as the CLI does
                error = ended.finished.message
        except InputError as exc:  # refused before anything moved (the rig busy, a question answered no)
            error = str(exc)
        except Exception as exc:  # the runner has already stopped the drives in its finally
            error = describe(exc, "the sweep stopped")
        finally:
            idle.set()
            self.post_message(SweepEnded(outcome, points, error, result=ended, run=ticket.run))

    def _ask_from_worker(self, question: str, control) -> bool:
        """Ask `question` in a dialog from a worker thread and wait for the answer (False when
        the job is aborted meanwhile, e.g. by quitting; "Cancel" is the default)."""
        answered = threading.Event()
        answer: list[bool] = []

        def show() -> None:
            self.push_screen(ConfirmScreen(question, yes="Sweep the compensated leg", no="Cancel"),
                             lambda yes: (answer.append(bool(yes)), answered.set()))

        self.call_from_thread(show)
        while not answered.wait(0.1):
            if control.aborted:
                return False
        return answer[0]

    def start_replay(self, source: Path, speed: float | None) -> bool:
        """Replay `source` through the replay devices and the sweep procedure (station.services.jobs.
        replay_sweep, the job `station replay` runs), recording a new session; shown on the Sweep screen.
        `speed`: None = as fast as possible, 1 = real time, N = N times faster."""
        if self.sweep.active:
            self.notify("A sweep is already running.", severity="warning")
            return False
        out = replay_output_path(self.cfg, source)
        ticket = self.jobs.claim(rig=False)  # the replay devices, not the rig
        self._begin_run(ticket, SweepState(out=out, label=f"replay of {source.name}", status="starting"), None)
        self._replay_worker(ticket, source, speed, out, self.sweep_control, self._sweep_idle)
        return True

    @work(thread=True, group="sweep", exit_on_error=False)
    def _replay_worker(self, ticket: Ticket, source: Path, speed: float | None, out: Path, control,
                       idle: threading.Event) -> None:
        run = ticket.run
        outcome, points, error, note = "error", 0, "", ""
        try:
            from station.services.replay_job import ReplayRequest, prepare_replay

            # the job `station replay` runs (its refusals: no plan to replay, ...), through the app's JobRunner
            job = prepare_replay(ReplayRequest(source, out, speed, make_parents=True), self.cfg)
            # the app keeps the replay rig as replay_rig (tests look at its devices)
            job.on_rig_opened = lambda rig: self.post_message(ReplayRigOpened(rig))
            ended = self.jobs.run(job, [TuiBridge(self, run)], control=control, ticket=ticket).data
            outcome, points = ended.result.outcome, ended.result.points
            if ended.mismatch is not None:
                error = describe(ended.mismatch, "the replay met a request the recording does not hold")
            elif ended.comparison is not None:
                cmp = ended.comparison
                note = ("identical to the recording" if cmp.identical
                        else "differs from the recording: " + "; ".join(cmp.differences[:2]))
        except Exception as exc:
            error = describe(exc, "the replay stopped")
        finally:
            idle.set()
            self.post_message(SweepEnded(outcome, points, error, note, run=run))


def _show_recorded_points(state: SweepState, points) -> None:
    """Put the points a resumed session holds already (`points`, its recorded rows) into `state`'s
    plot, so a resumed sweep shows its whole session (the procedure's SweepStarted then sets the counts)."""
    for r in points:
        state.traces.setdefault(int(r["leg"]), LegTrace()).add(float(r["target_mm"]), float(r["error_um"]),
                                                               int(r["direction"]))
    state.done = state.resumed_points = len(points)
