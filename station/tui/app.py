"""The station's terminal UI: one Textual app, one mode (screen stack) per task.

The app owns the rig connection and the sweep job, so a sweep survives screen changes and
redraws: the screens only draw from `app.sweep` (a `SweepState`) and call the app's actions.
All device I/O runs in thread workers; results come back as messages. Device access is
serialised by `rig_lock` (the sweep holds it for its whole run; status polling skips a beat
instead of waiting), except the quick stop of an abort, which must not wait for anything.

One owner: the app's thread is the only one that assigns the app's state (`rig`, `rig_state`,
`rig_error`, `sweep`, `sweep_control`, `replay_rig`, ...) or folds events into `sweep`. A worker
gets the rig, the lock and the run control as arguments and reports back only with messages
(station.tui.messages, station.tui.bridge). After a change the app posts `SweepChanged` /
`RigStateChanged` to the screens on show, which redraw from it: no screen polls the app's state.
Pause, resume and abort are asked for in one place each (`action_pause_sweep`,
`action_abort_sweep`); the status shown follows the procedure's Paused / Resumed / SweepFinished
events (`SweepState.apply`).
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Callable

from textual import work
from textual.app import App
from textual.binding import Binding
from textual.message import Message
from textual.notifications import Notification, Notify

from procedures.vocabulary import InputError
from station.services.config import StationConfig
from station.services.job import JobRunner, RigBusy, Ticket
from station.services.rig_session import (
    JOB_LOCK_WAIT_S,
    ActionRefused,
    MoveRequest,
    MoveStopped,
    RigSession,
    checked_move,
    close_quietly,
    rig_action,
)
from station.services.sweep_job import OutputExists, SweepRequest, prepare_sweep
from station.services.sessions import replay_output_path
from station.tui.bridge import SweepEnded, SweepEvent, TuiBridge
from station.tui.error_text import describe
from station.tui.messages import (
    Notice,
    ReplayRigOpened,
    RigActionDone,
    RigConnected,
    RigConnectFailed,
    RigStateChanged,
    SweepChanged,
)
from station.tui.screens.common import ConfirmScreen
from station.tui.screens.compensation import CompensationScreen
from station.tui.screens.diagnosis import DiagnosisScreen
from station.tui.screens.help import HelpScreen
from station.tui.screens.history import HistoryScreen
from station.tui.screens.platform import PlatformScreen
from station.tui.screens.replay import ReplayScreen
from station.tui.screens.results import ResultsScreen
from station.tui.screens.rig import RigScreen
from station.tui.screens.sweep import SweepScreen
from station.tui.state import LegTrace, SweepState, event_notice

ALL_LEGS = (1, 2, 3, 4, 5, 6)
# The keys of the rig actions a refusal names as the way out (station.services.rig_session.REMEDIES).
RIG_KEYS = {"reset": "r", "enable": "e", "stop": "x"}
# The ways out of a refused sweep of a compensated leg, on this UI (station.services.jobs.compensated_refusal).
UI_WAYS_OUT = {"rollback": "b on the Compensation page, F4", "confirm": "answer yes when asked"}
# How long quitting waits for an aborted sweep to stop the drives and close its recording.
QUIT_WAIT_S = 15.0


class RigMoveDone(Message):
    """A "move" rig action ended. `error` is "" when the leg arrived at `position_mm`; else why
    it did not move, or where it stopped (`stopped`: quick-stopped on the way)."""

    def __init__(self, leg: int, error: str = "", position_mm: float | None = None, speed_mm_s: float | None = None,
                 stopped: bool = False) -> None:
        super().__init__()
        self.leg = leg
        self.error = error
        self.position_mm = position_mm
        self.speed_mm_s = speed_mm_s
        self.stopped = stopped


class StationApp(App):
    """The calibration station UI.

    `cfg`: station config (None = simulated rig with built-in defaults). `time_scale`: simulated
    rig only, real seconds per simulated second (None = the config's). `replay`: a session file
    to open on the Replay screen. `autoconnect`: connect to the rig at start. `hide_volatile`:
    hide clocks, ETAs, device addresses and file paths (for snapshot tests). `poll_interval_s`:
    how often the Rig screen reads drive and interferometer status.
    """

    TITLE = "station"
    SUB_TITLE = "leg calibration"
    CSS_PATH = Path(__file__).with_name("station.tcss")  # absolute: subclasses (tests) find it too
    MODES = {
        "rig": RigScreen,
        "sweep": SweepScreen,
        "results": ResultsScreen,
        "compensation": CompensationScreen,
        "replay": ReplayScreen,
        "diagnosis": DiagnosisScreen,
        "platform": PlatformScreen,
        "history": HistoryScreen,
    }
    DEFAULT_MODE = "rig"
    SESSION = RigSession  # the rig session's class (tests record its assignments)
    # The screens are told of sweep changes at most this often (s): a fast sweep folds many
    # events in between, and one redraw shows them all.
    SWEEP_REDRAW_S = 0.1
    # The page keys (F1-F7) are shown in the tab bar at the top of every page; the footer keeps
    # the current page's actions, the help (?, F12: every page's keys) and quit.
    BINDINGS = [
        Binding("f1", "switch_mode('rig')", "Rig", show=False),
        Binding("f2", "switch_mode('sweep')", "Sweep", show=False),
        Binding("f3", "switch_mode('results')", "Results", show=False),
        Binding("f4", "switch_mode('compensation')", "Compensation", show=False),
        Binding("f5", "switch_mode('replay')", "Replay", show=False),
        Binding("f6", "switch_mode('diagnosis')", "Diagnosis", show=False),
        Binding("f7", "switch_mode('platform')", "Platform", show=False),
        Binding("f8", "switch_mode('history')", "History", show=False),
        Binding("question_mark", "station_help", "Help", key_display="?"),
        Binding("f12", "station_help", "Help", show=False),
        Binding("ctrl+q", "quit", "Quit", priority=True),
        Binding("ctrl+c", "quit", "Quit", show=False, priority=True),
    ]

    def __init__(
        self,
        cfg: StationConfig | None = None,
        *,
        time_scale: float | None = None,
        replay: str | Path | None = None,
        legs: tuple[int, ...] = ALL_LEGS,
        autoconnect: bool = True,
        hide_volatile: bool = False,
        poll_interval_s: float = 1.0,
    ) -> None:
        super().__init__()
        self.cfg = cfg or StationConfig()
        self.time_scale = time_scale
        self.replay_path = Path(replay) if replay else None
        self.legs = tuple(legs)
        self.autoconnect = autoconnect
        self.hide_volatile = hide_volatile
        self.poll_interval_s = poll_interval_s
        # Assigned on the app's thread only (see the module docstring): the rig connection, its
        # lock, the move under way (station.services.rig_session).
        self.session = self.SESSION(self.cfg, self.legs, time_scale)
        self.sweep = SweepState()
        self.sweep_control = None  # the RunControl of the job on show (its ticket's)
        # the one runner of the rig jobs: the rig lock (the session's, which rig actions share),
        # run numbering, abort (station/services/job.py)
        self.jobs = JobRunner(lock=self.session.lock, wait_s=JOB_LOCK_WAIT_S)
        self._sweep_idle = threading.Event()  # set by the job's worker when it has returned
        self._sweep_idle.set()
        self._quit_after_sweep = False
        self.replay_rig = None  # the replay devices of the running (or last) replay
        # run number -> (its SweepState, its on_done), until its SweepEnded has been handled
        self._runs: dict[int, tuple[SweepState, Callable[[SweepState], None] | None]] = {}
        self._sweep_redraw_due = None  # the Timer of the coalesced SweepChanged still to post
        self._sweep_told_at = -1e9  # time.monotonic() of the last SweepChanged posted
        self.last_session: Path | None = None  # the newest recording made or opened here
        self.analysis = None  # results.Analysis: the session, model and ISO figures on show (Compensation, Platform use it)
        self.session_listeners: list[Callable[[Path], None]] = []
        self._stop_notices: dict[int, list[Notification]] = {}  # leg -> its quick stop's notifications on show

    # -- the rig session's state, as the screens read it ----------------------------------------
    @property
    def rig(self):
        """station.services.wiring.Rig once connected, else None."""
        return self.session.rig

    @rig.setter
    def rig(self, rig) -> None:
        self.session.rig = rig

    @property
    def rig_state(self) -> str:
        return self.session.state  # "connecting" / "connected" / "not connected"

    @property
    def rig_error(self) -> str:
        return self.session.error

    @property
    def rig_lock(self) -> threading.Lock:
        return self.session.lock

    @property
    def rig_motion(self) -> dict[int, MoveRequest]:
        return self.session.motion  # leg -> the move/jog under way (Rig page)

    @property
    def rig_motion_text(self) -> str:
        return self.session.motion_text  # how the last move/jog ended, for the Rig page

    # -- lifecycle -------------------------------------------------------------------------
    def on_mount(self) -> None:
        if self.replay_path is not None:
            self.last_session = self.replay_path
            self.switch_mode("replay")
        if self.autoconnect:
            self.connect_rig()

    def on_unmount(self) -> None:
        # Last line of defence (e.g. the terminal closed): stop motion, close the recording.
        # Not through action_abort_sweep: no worker starts and nothing is drawn any more, so the
        # abort is sent from here and waited for.
        if self.sweep_control is not None and not self._sweep_idle.is_set():
            self.sweep_control.abort("the station UI closed")
            self._sweep_idle.wait(QUIT_WAIT_S)
        self.session.close()

    # -- notifications -----------------------------------------------------------------------
    def on_notice(self, message: Notice) -> None:
        self.notify(message.text, title=message.title, severity=message.severity,  # type: ignore[arg-type]
                    timeout=12 if message.severity == "error" else 6)

    def action_station_help(self) -> None:
        """Open the key help (every page's keys, from their BINDINGS), or close it when open."""
        if isinstance(self.screen, HelpScreen):
            self.screen.dismiss()
        else:
            self.push_screen(HelpScreen())

    def set_session(self, path: Path) -> None:
        """Make `path` the session the Results/Compensation/Diagnosis screens work on."""
        self.last_session = Path(path)
        for listener in list(self.session_listeners):
            listener(self.last_session)

    # -- rig connection ------------------------------------------------------------------------
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

    def action_connect(self) -> None:
        refusal = self.sweep_refusal()
        if refusal:
            self.notify(refusal, title="Reconnect", severity="warning")
            return
        self.connect_rig()

    def connect_rig(self) -> None:
        """(Re)connect. The current rig is detached here, on the app's thread, so `app.rig` never
        names a rig that is being closed; the worker closes it, then opens the new one."""
        old, attempt = self.session.detach()
        self._rig_changed()
        self._connect_worker(old, attempt, self.session.lock)

    @work(thread=True, group="connect", exit_on_error=False)
    def _connect_worker(self, old, attempt: int, lock: threading.Lock) -> None:
        try:  # a poll or an action still using the old rig finishes first (the session takes the lock)
            rig = self.session.open_rig_for(old, lock)
        except Exception as exc:
            self.post_message(RigConnectFailed(describe(exc, "cannot connect to the rig"), attempt))
            return
        self.post_message(RigConnected(rig, attempt))

    def on_rig_connected(self, message: RigConnected) -> None:
        if not self.session.accept(message.rig, message.attempt):  # a newer connect request is under way
            self._close_worker(message.rig)
            return
        self.notify(f"Connected: {self._rig_kind_text()}.", timeout=4)
        self._rig_changed()

    def on_rig_connect_failed(self, message: RigConnectFailed) -> None:
        if not self.session.fail(message.error, message.attempt):
            return
        self.notify(message.error + " Press c on the Rig screen (F1) to retry.", title="Rig",
                    severity="error", timeout=15)
        self._rig_changed()

    @work(thread=True, group="connect", exit_on_error=False)
    def _close_worker(self, rig) -> None:
        close_quietly(rig, "closing a superseded rig failed")

    def _rig_changed(self) -> None:
        """Tell the screens on show that the connection changed (the others redraw when shown)."""
        self._tell_screens(RigStateChanged)

    def _rig_kind_text(self) -> str:
        return self.session.kind_text(self.hide_volatile)

    # -- rig actions (enable, disable, home, reset, stop, move) ----------------------------------
    def rig_action(self, action: str, legs: tuple[int, ...], move: MoveRequest | None = None) -> bool:
        """Run a rig action on `legs` in a worker; True if it was started. Refused while a sweep
        holds the rig (except "stop", which always goes through and quick-stops a move too).
        "move" takes one leg and `move` (where to, how fast); it is refused while another move
        runs, and the worker refuses it on a leg in fault or not enabled, or beyond the drive's
        soft limits, before anything moves (station.services.rig_session.move_axis)."""
        if self.rig is None:
            self.notify("Not connected to the rig: press c on the Rig screen to connect.", severity="warning")
            return False
        refusal = self.sweep_refusal() if action != "stop" else ""
        if refusal:
            self.notify(refusal, title=f"{action} leg {', '.join(str(leg) for leg in legs)}", severity="warning")
            return False
        if action == "move":
            if move is None or len(legs) != 1:
                raise ValueError("a move is one leg's, with its MoveRequest")
            refusal = self.session.move_refusal()
            if refusal is not None:
                self.notify(refusal.say(RIG_KEYS), title=f"move leg {legs[0]}", severity="warning")
                return False
            self.session.begin_move(legs[0], move)
            self._rig_changed()
        self._rig_action_worker(self.rig, self.rig_lock, action, legs, move)
        return True

    @work(thread=True, group="rig-action", exit_on_error=False)
    def _rig_action_worker(self, rig, lock: threading.Lock, action: str, legs: tuple[int, ...],
                           move: MoveRequest | None = None) -> None:
        if action == "move":
            self._move_worker_body(rig, lock, legs[0], move)
            return
        try:
            rig_action(rig, lock, action, legs)
        except ActionRefused as exc:
            self.post_message(RigActionDone(action, legs, exc.say(RIG_KEYS)))
            return
        except Exception as exc:
            self.post_message(RigActionDone(action, legs, describe(exc, f"{action} failed")))
            return
        self.post_message(RigActionDone(action, legs))

    def _move_worker_body(self, rig, lock: threading.Lock, leg: int, move: MoveRequest) -> None:
        """The "move" action, on the rig-action worker: always ends with one RigMoveDone."""
        done = RigMoveDone(leg, "the move stopped before it began (see the log)")
        try:
            position, speed = checked_move(rig, lock, leg, move)
            done = RigMoveDone(leg, position_mm=position, speed_mm_s=speed)
        except MoveStopped as exc:
            done = RigMoveDone(leg, exc.say(RIG_KEYS), stopped=True)
        except ActionRefused as exc:
            done = RigMoveDone(leg, exc.say(RIG_KEYS))
        except Exception as exc:
            done = RigMoveDone(leg, describe(exc, f"move of leg {leg} failed"))
        finally:
            self.post_message(done)

    def on_rig_action_done(self, message: RigActionDone) -> None:
        legs = ", ".join(str(leg) for leg in message.legs)
        if message.error:
            self.notify(message.error, title=f"{message.action} leg {legs}", severity="error", timeout=12)
        else:
            if message.action == "enable":  # the quick stop is over: its toasts ("enable it (e)") go
                for leg in message.legs:
                    for notification in self._stop_notices.pop(leg, []):
                        if notification in self._notifications:
                            self._unnotify(notification)
            self.notify(f"{message.action}: leg {legs} done.", timeout=3)

    def on_rig_move_done(self, message: RigMoveDone) -> None:
        if message.error:
            self.session.end_move(message.leg, message.error)
            if message.stopped:  # kept, to be taken down when the leg is enabled again
                notification = Notification(message.error, f"move leg {message.leg}", "warning", 12)
                self._stop_notices.setdefault(message.leg, []).append(notification)
                self.post_message(Notify(notification))
            else:
                self.notify(message.error, title=f"move leg {message.leg}", severity="error", timeout=12)
        else:
            self.session.end_move(message.leg, f"leg {message.leg} at {message.position_mm:+.4f} mm "
                                               f"(moved at {message.speed_mm_s:g} mm/s)")
            self.notify(f"move: {self.rig_motion_text}.", timeout=3)
        self._rig_changed()

    # -- jobs on the rig: the sweep, a resumed sweep, a verification ----------------------------------
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

    def on_replay_rig_opened(self, message: ReplayRigOpened) -> None:
        self.replay_rig = message.rig

    def on_sweep_event(self, message: SweepEvent) -> None:
        run = self._runs.get(message.run)
        if run is None:  # its job has ended already (an event after its end: nothing to show)
            return
        s = run[0]
        if s.apply(message.event) and s is self.sweep:
            self._sweep_changed()
        notice = event_notice(message.event, s.label)
        if notice is not None:
            self.notify(notice.text, title=notice.title, severity=notice.severity,  # type: ignore[arg-type]
                        timeout=notice.timeout)

    def on_sweep_ended(self, message: SweepEnded) -> None:
        run = self._runs.pop(message.run, None)
        if run is None:
            return
        s, done = run
        if s.active:  # no SweepFinished came: the run broke off with an exception
            s.status = "error" if message.error else message.outcome
            s.reason = message.error
        s.note = message.note
        s.result = message.result
        if s is self.sweep:
            self._sweep_changed()
        if message.error:
            self.notify(message.error, title="Sweep", severity="error", timeout=15)
        else:
            written = s.out is not None and s.out.exists()  # no hint names a file never written
            resume = " Finish it later: r on the Sweep page (F2)." if s.label == "sweep" and written else ""
            note = {"completed": "completed." + (" Results: F3." if s.label == "sweep" else ""),
                    "aborted": ("aborted; drives stopped, recording kept." if written else
                                "aborted before it began; nothing moved, nothing recorded.") + resume,
                    "failed": f"failed: {s.reason}" + resume}.get(s.status, s.status)
            extra = f"; {s.note}" if s.note else ""
            self.notify(f"{s.label.capitalize()} {note} ({s.done} of {s.total} points){extra}", title="Sweep",
                        severity="information" if s.status == "completed" else "warning", timeout=8)
        if s.out is not None and s.out.exists():
            self.set_session(s.out)
        if done is not None:
            try:
                done(s)
            except Exception as exc:  # a follow-up must not take the app down
                self.notify(describe(exc, f"after the {s.label}"), severity="error", timeout=12)
        if self._quit_after_sweep and s is self.sweep:
            self.exit()

    # -- telling the screens -----------------------------------------------------------------------
    def _sweep_changed(self) -> None:
        """`app.sweep` changed: post `SweepChanged` to the screens on show, at once when the last
        one is `SWEEP_REDRAW_S` old, else once at the end of that interval (a single one for
        every change in between)."""
        if self._sweep_redraw_due is not None:
            return  # one is due already; it shows this change too
        wait = self._sweep_told_at + self.SWEEP_REDRAW_S - time.monotonic()
        if wait <= 0:
            self._post_sweep_changed()
        else:
            self._sweep_redraw_due = self.set_timer(wait, self._post_sweep_changed, name="sweep-changed")

    def _post_sweep_changed(self) -> None:
        self._sweep_redraw_due = None
        self._sweep_told_at = time.monotonic()
        self._tell_screens(SweepChanged)

    def _tell_screens(self, message_type: type) -> None:
        """Post a new `message_type()` to each screen of the current page's stack (a dialog and
        the page under it); a page not on show redraws when it is shown again."""
        try:
            screens = list(self.screen_stack)
        except Exception:  # no screen yet (the app is starting or has ended)
            return
        for screen in screens:
            screen.post_message(message_type())

    # -- pause, resume, abort: asked for here only -----------------------------------------------
    def _control_of_running_sweep(self):
        if not self.sweep.active or self.sweep_control is None:
            self.notify("No sweep is running.", severity="warning")
            return None
        return self.sweep_control

    def action_pause_sweep(self) -> None:
        """Pause between points (nothing moves while paused), or resume: the one place the UI
        asks for either. The status on show changes when the procedure has paused or resumed
        (its Paused / Resumed events, folded in by on_sweep_event), not here."""
        control = self._control_of_running_sweep()
        if control is None or self.sweep.status == "aborting":
            return
        if control.paused:
            control.resume()
            self.notify("Resuming the sweep.", timeout=3)
        else:
            control.pause()
            self.notify("Pausing after the current point…", timeout=3)

    def action_abort_sweep(self) -> None:
        """Abort: quick-stop the axes now (from a worker, the UI stays live), end the sweep. The
        one place the UI asks for an abort (the Rig page's stop-all and quitting come here too);
        the status shows "aborting" (SweepState.request_abort) until SweepFinished says how it ended."""
        control = self._control_of_running_sweep()
        if control is None:
            return
        if self.sweep.request_abort():
            self._sweep_changed()
            self._abort_worker(control)
            self.notify("Aborting: stopping the drives…", severity="warning", timeout=4)

    @work(thread=True, group="abort", exit_on_error=False)
    def _abort_worker(self, control) -> None:
        control.abort("aborted by the operator")

    # -- quitting --------------------------------------------------------------------------------
    async def action_quit(self) -> None:
        if self._quit_after_sweep:
            return
        if self.sweep.active:
            legs = ", ".join(str(leg) for leg in self.sweep.legs)

            def confirmed(yes: bool | None) -> None:
                if yes and not self.sweep.active:  # it ended while the question was open
                    self.exit()
                elif yes:
                    self._quit_after_sweep = True
                    self.action_abort_sweep()
                    self.notify("Stopping the drives and closing the recording, then quitting…", timeout=10)

            self.push_screen(
                ConfirmScreen(
                    f"A {self.sweep.label} is running on leg {legs}.\n\nQuit anyway? It is aborted, the drives "
                    "are stopped and disabled, and the recording is kept"
                    + (f" (finish it later with r on the Sweep page, or `station sweep --resume {self.sweep.out}`)."
                       if self.sweep.label == "sweep" and self.sweep.out is not None and self.sweep.out.exists()
                       else "."),
                    yes="Abort and quit", no="Keep sweeping",
                ),
                confirmed,
            )
            return
        self.exit()


def _show_recorded_points(state: SweepState, points) -> None:
    """Put the points a resumed session holds already (`points`, its recorded rows) into `state`'s
    plot, so a resumed sweep shows its whole session (the procedure's SweepStarted then sets the counts)."""
    for r in points:
        state.traces.setdefault(int(r["leg"]), LegTrace()).add(float(r["target_mm"]), float(r["error_um"]),
                                                               int(r["direction"]))
    state.done = state.resumed_points = len(points)
