"""One owner for the app's state: only the UI thread assigns the rig and the sweep state, the
status follows the procedure's events, and the screens redraw from messages, not timers.

The rig tests run the simulated rig at time scale 0 (real Modbus TCP + serial pty).
"""

from __future__ import annotations

import asyncio
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
from textual.widgets import ProgressBar, Static

from procedures.engine import events as ev
from procedures.acquisition.plans import iso230_plan
from procedures.vocabulary import Outcome
from tests.tooling import start_paper_sweep
from station.services.job import JobOutcome
from station.services.rig_session import RigSession
from station.tui.app import StationApp
from station.tui.messages import SweepChanged
from station.tui.state import SweepState

pytestmark = pytest.mark.timeout(180)

# What the app's workers used to assign, and what the app owns besides.
OWNED = ("rig", "rig_state", "rig_error", "sweep", "sweep_control", "replay_rig", "last_session", "analysis",
         "_quit_after_sweep", "_connect_attempt", "_sweep_run", "_runs")


class RecordingSession(RigSession):
    """Records the thread of every assignment on the app's rig session (station.services.
    rig_session), under the app's names for them (`state` is the app's `rig_state`)."""

    NAMES = {"state": "rig_state", "error": "rig_error", "motion_text": "rig_motion_text",
             "_attempt": "_connect_attempt"}

    def __init__(self, *args, **kwargs) -> None:
        object.__setattr__(self, "writes", [])
        super().__init__(*args, **kwargs)

    def __setattr__(self, name, value) -> None:
        self.writes.append((self.NAMES.get(name, name), threading.current_thread(), value))
        super().__setattr__(name, value)


class RecordingApp(StationApp):
    """Records the thread of every assignment of an attribute on the app and its rig session."""

    SESSION = RecordingSession

    def __init__(self, *args, **kwargs) -> None:
        object.__setattr__(self, "_writes", [])  # (attribute, thread name, value)
        object.__setattr__(self, "connected", [])  # (rig, attempt) of every RigConnected, in arrival order
        super().__init__(*args, **kwargs)

    def on_rig_connected(self, message) -> None:
        # (Textual calls StationApp's own handler after this one: it walks the class's MRO)
        self.connected.append((message.rig, message.attempt))

    @property
    def writes(self) -> list:
        return self._writes + self.session.writes

    def __setattr__(self, name, value) -> None:
        self._writes.append((name, threading.current_thread(), value))
        super().__setattr__(name, value)


def off_ui_thread(writes, ui: threading.Thread) -> list[str]:
    return [f"{name} = {value!r:.60} on {thread.name}" for name, thread, value in writes if thread is not ui]


class RigTracker:
    """Wraps station.services.wiring.open_rig: every rig opened, and the thread each was closed on."""

    def __init__(self, monkeypatch) -> None:
        import station.services.wiring

        self.opened: list = []
        self.closed: dict[int, threading.Thread] = {}
        real = station.services.wiring.open_rig

        def open_rig(*args, **kwargs):
            rig = real(*args, **kwargs)
            close = rig.close

            def tracked_close() -> None:
                self.closed.setdefault(id(rig), threading.current_thread())
                close()

            rig.close = tracked_close
            self.opened.append(rig)
            return rig

        monkeypatch.setattr(station.services.wiring, "open_rig", open_rig)

    def is_closed(self, rig) -> bool:
        return rig is not None and id(rig) in self.closed


def test_only_the_ui_thread_assigns_the_rig_and_the_sweep_state(cfg, size, connected, wait_until, recorded_session,
                                                               monkeypatch):
    tracker = RigTracker(monkeypatch)
    applied: list[threading.Thread] = []
    real_apply = SweepState.apply

    def apply(self, event):
        applied.append(threading.current_thread())
        return real_apply(self, event)

    monkeypatch.setattr(SweepState, "apply", apply)
    asyncio.run(_only_the_ui_thread(cfg, size, connected, wait_until, recorded_session, tracker, applied))


async def _only_the_ui_thread(cfg, size, connected, wait_until, recorded_session, tracker, applied):
    ui = threading.current_thread()  # run_test runs the app on this thread's event loop
    app = RecordingApp(cfg, time_scale=0.0, legs=(1, 2), poll_interval_s=0.05)

    async def wait_never_closed(condition, what: str, timeout_s: float = 30.0) -> None:
        """Wait for `condition`, checking on every frame that app.rig never names a closed rig."""
        def check() -> bool:
            assert not tracker.is_closed(app.rig), f"app.rig names a closed rig while waiting for {what}"
            return condition()

        await wait_until(pilot, check, timeout_s, what)

    async with app.run_test(size=size) as pilot:
        await connected(pilot)
        first = app.rig
        assert not tracker.is_closed(first)

        # reconnect while connected: the UI thread detaches the rig at once, a worker closes it
        app.action_connect()
        assert app.rig is None and app.rig_state == "connecting"
        await wait_never_closed(lambda: app.rig_state == "connected", "the reconnection")
        second = app.rig
        assert second is not first and not tracker.is_closed(second)
        assert tracker.is_closed(first) and tracker.closed[id(first)] is not ui

        # two requests in a row: the newer one's rig is kept, the superseded one's is closed
        app.action_connect()
        app.action_connect()
        # (both requests' rigs opened: the first one's may open after the second's, so the count is
        # part of the wait, not only of the assertion below)
        await wait_never_closed(lambda: app.rig_state == "connected" and len(tracker.opened) == 4
                                and len(tracker.closed) == len(tracker.opened) - 1, "the second reconnection")
        # the rig kept is the one that answered the newer request, whichever of the two opened last
        (rig_a, attempt_a), (rig_b, attempt_b) = app.connected[-2:]
        newer, older = (rig_a, rig_b) if attempt_a > attempt_b else (rig_b, rig_a)
        assert {attempt_a, attempt_b} == {app.session._attempt - 1, app.session._attempt}
        assert app.rig is newer and not tracker.is_closed(newer)
        await wait_never_closed(lambda: tracker.is_closed(older), "the superseded rig to be closed")
        assert len(tracker.opened) == 4  # one per connect request: at start, the reconnection, these two

        # a sweep, paused, resumed and aborted through the app's actions
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep screen")
        await start_paper_sweep(pilot, "1")
        await wait_never_closed(lambda: app.sweep.done >= 3, "first points")
        app.action_pause_sweep()
        assert app.sweep.status == "running"  # asked for: the status waits for the procedure's Paused
        await wait_never_closed(lambda: app.sweep.status == "paused", "the pause")
        app.action_pause_sweep()
        assert app.sweep.status == "paused"  # asked for: the status waits for Resumed
        await wait_never_closed(lambda: app.sweep.status == "running", "the resume")
        app.action_abort_sweep()
        assert app.sweep.status == "aborting"  # the one request state, set by the abort action
        await wait_never_closed(lambda: not app.sweep.active, "the abort")
        assert app.sweep.status == "aborted"

        # a replay: its devices come back in a message
        assert app.start_replay(recorded_session, None)
        await wait_never_closed(lambda: app.sweep.status == "completed" and app.sweep.note, "the replay", 60)
        assert app.replay_rig is not None
        assert [t for name, t, value in app.writes if name == "replay_rig" and value is not None] == [ui]
        await pilot.press("ctrl+q")

    assert applied and set(applied) == {ui}, "sweep events were folded in off the UI thread"
    assert off_ui_thread(app.writes, ui) == []
    written = {name for name, _, _ in app.writes}
    assert {"rig", "rig_state", "sweep", "sweep_control", "replay_rig", "last_session"} <= written
    # every rig opened is closed (the last one when the app ended), none by the UI thread but that one
    assert len(tracker.closed) == len(tracker.opened)
    assert [id(r) for r in tracker.opened if tracker.closed[id(r)] is ui] == [id(tracker.opened[-1])]


def record(i: int, leg: int = 1) -> dict[str, float]:
    return {"index": i, "leg": leg, "run": i // 10, "target_mm": -90.0 + i, "error_um": 0.5 * i,
            "direction": 1 if (i // 10) % 2 == 0 else -1, "air_temp_c": 20.0, "air_pressure_hpa": 1013.0,
            "humidity_pct": 45.0, "material_temp_c": 20.5, "load_n": 100.0, "signal_pct": 90.0}


def status_text(app) -> str:
    return str(app.screen.query_one("#sweep-status", Static).render())


def test_the_sweep_screen_redraws_on_a_sweep_changed_message_not_on_a_timer(cfg, size, wait_until):
    asyncio.run(_redraws_on_message(cfg, size, wait_until))


async def _redraws_on_message(cfg, size, wait_until):
    app = StationApp(cfg, autoconnect=False, hide_volatile=True)
    async with app.run_test(size=size) as pilot:
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep screen")
        screen = app.screen
        assert "no sweep yet" in status_text(app)
        # the state changes (here, on the UI thread) without a message: nothing polls it
        app.sweep = SweepState(legs=(1,), status="running", total=20)
        for i in range(7):
            app.sweep.apply(ev.PointMeasured(record(i), done=i + 1, total=20))
        await pilot.pause(0.6)  # three times the old poll interval
        assert "no sweep yet" in status_text(app)
        assert screen.query_one("#progress", ProgressBar).progress == 0
        # the message redraws it
        screen.post_message(SweepChanged())
        await wait_until(pilot, lambda: "7/20 points" in status_text(app), 5, "the redraw")
        assert screen.query_one("#progress", ProgressBar).progress == 7
        assert "running" in status_text(app)


def test_a_burst_of_events_reaches_the_sweep_screen_in_few_coalesced_redraws(cfg, size, wait_until):
    asyncio.run(_burst(cfg, size, wait_until))


async def _burst(cfg, size, wait_until):
    n = 2000
    plan = iso230_plan((1,), -90.0, 90.0, step_mm=18.0, cycles=1)
    go = threading.Event()

    def run(sinks, control):
        """A job without hardware: the events of a sweep of `n` points, as fast as they come."""
        go.wait(10)
        bridge = sinks[0]
        bridge.handle(ev.SweepStarted("s", (1,), n, {}, {}))
        for i in range(n):
            bridge.handle(ev.PointMeasured(record(i), done=i + 1, total=n))
        bridge.handle(ev.SweepFinished(Outcome.COMPLETED, n))
        return JobOutcome(Outcome.COMPLETED, run=SimpleNamespace(outcome=Outcome.COMPLETED, points=n))

    # a prepared rig job (station/services/job.py) of the plan's legs and size
    job = SimpleNamespace(needs_rig=True, question=None, lines=[], out=Path(cfg.recordings_dir) / "burst.h5",
                          legs=plan.legs, kind=plan.kind, total_points=plan.total_points, run=run)

    app = StationApp(cfg, autoconnect=False, hide_volatile=True)
    async with app.run_test(size=size) as pilot:
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen.MODE == "sweep", what="the Sweep screen")
        screen = app.screen
        redraws: list[float] = []
        draw = screen._redraw

        def counted() -> None:
            redraws.append(time.monotonic())
            draw()

        screen._redraw = counted
        app.rig = SimpleNamespace(axes={1: None}, close=lambda: None)  # the job needs no device
        assert app.start_job(job)
        t0 = time.monotonic()
        go.set()
        await wait_until(pilot, lambda: not app.sweep.active and f"{n}/{n} points" in status_text(app), 30,
                         "the last point on screen")
        elapsed = time.monotonic() - t0
        assert app.sweep.status == "completed" and app.sweep.done == n
        assert screen.query_one("#progress", ProgressBar).progress == n
        # at most one redraw per SWEEP_REDRAW_S, not one per event
        assert len(redraws) <= elapsed / app.SWEEP_REDRAW_S + 3, (len(redraws), elapsed)
