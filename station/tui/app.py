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

This module is the composition: the app's state (all of it assigned in `StationApp.__init__`),
its lifecycle, and its parts, one module each, named for what they hold:
  station.tui.pages           the pages (modes) and the keys of every page (F1-F8, help, quit)
  station.tui.rig_connection  the rig session, (re)connecting in a worker, the rig's state
  station.tui.rig_actions     enable, disable, home, reset, stop and move in a worker
  station.tui.job_dispatch    starting a sweep, resume, verification or replay through `app.jobs`
  station.tui.job_events      a job's events folded into its SweepState, its end shown
  station.tui.job_control     pause, resume, abort of the job on show, and quitting while it runs
  station.tui.redraws         telling the screens on show to redraw (SweepChanged, RigStateChanged)
Each part is a mixin of the app (its `self` is the app), so its workers (`@work`) and message
handlers are the app's own, as in Textual's workers guide.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Callable

from textual.app import App
from textual.notifications import Notification

from station.services.config import StationConfig
from station.services.job import JobRunner
from station.services.rig_session import JOB_LOCK_WAIT_S, RigSession
from station.tui.job_control import JobControl
from station.tui.job_dispatch import JobDispatch
from station.tui.job_events import JobEvents
from station.tui.messages import Notice
from station.tui.pages import APP_KEYS, PAGE_MODES, PageKeys
from station.tui.redraws import Redraws
from station.tui.rig_actions import RigActions
from station.tui.rig_connection import RigConnection
from station.tui.state import SweepState

ALL_LEGS = (1, 2, 3, 4, 5, 6)


class StationApp(PageKeys, RigConnection, RigActions, JobDispatch, JobEvents, JobControl, Redraws, App):
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
    MODES = PAGE_MODES
    DEFAULT_MODE = "rig"
    SESSION = RigSession  # the rig session's class (tests record its assignments)
    BINDINGS = APP_KEYS

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

    # -- lifecycle -------------------------------------------------------------------------
    def on_mount(self) -> None:
        if self.replay_path is not None:
            self.last_session = self.replay_path
            self.switch_mode("replay")
        if self.autoconnect:
            self.connect_rig()

    def on_unmount(self) -> None:
        # Last line of defence (e.g. the terminal closed): stop motion, close the recording.
        self._abort_on_close()
        self.session.close()

    # -- notifications -----------------------------------------------------------------------
    def on_notice(self, message: Notice) -> None:
        self.notify(message.text, title=message.title, severity=message.severity,  # type: ignore[arg-type]
                    timeout=12 if message.severity == "error" else 6)

    def set_session(self, path: Path) -> None:
        """Make `path` the session the Results/Compensation/Diagnosis screens work on."""
        self.last_session = Path(path)
        for listener in list(self.session_listeners):
            listener(self.last_session)
