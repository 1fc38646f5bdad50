"""Messages: from worker threads to the app (never widget calls from a thread, never an
assignment on the app), and from the app to the screens when what they show has changed.

The app's thread is the only writer of the app's state (`app.rig`, `app.rig_state`,
`app.sweep`, `app.sweep_control`, `app.replay_rig`, ...): a worker gets what it needs as
arguments and reports back with one of these messages, which the app folds in on its thread.
"""

from __future__ import annotations

from typing import Any

from textual.message import Message


class RigConnected(Message):
    """A connect worker opened `rig`; `attempt` names the connect request it answers (the app
    takes only the newest one's rig and has an older one closed)."""

    def __init__(self, rig: Any, attempt: int = 0) -> None:
        super().__init__()
        self.rig = rig
        self.attempt = attempt


class RigConnectFailed(Message):
    def __init__(self, error: str, attempt: int = 0) -> None:
        super().__init__()
        self.error = error
        self.attempt = attempt


class ReplayRigOpened(Message):
    """The replay worker opened its replay devices (`rig`): the app keeps them as `replay_rig`."""

    def __init__(self, rig: Any) -> None:
        super().__init__()
        self.rig = rig


class RigActionDone(Message):
    """A rig action (enable, home, reset, stop) finished; `error` is "" on success."""

    def __init__(self, action: str, legs: tuple[int, ...], error: str = "") -> None:
        super().__init__()
        self.action = action
        self.legs = legs
        self.error = error


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


class Notice(Message):
    """A notification to show (severity: information / warning / error)."""

    def __init__(self, text: str, severity: str = "information", title: str = "") -> None:
        super().__init__()
        self.text = text
        self.severity = severity
        self.title = title


class SweepChanged(Message):
    """Posted by the app to the screens on show after it changed `app.sweep` (an event folded
    in, a sweep started or ended, an abort requested): redraw what shows the sweep. Coalesced by
    the app (at most one per `StationApp.SWEEP_REDRAW_S`), so a fast sweep does not flood the UI."""

    bubble = False  # each screen gets its own; the app is not told again


class RigStateChanged(Message):
    """Posted by the app to the screens on show after the connection changed (`app.rig`,
    `app.rig_state`, `app.rig_error`)."""

    bubble = False
