"""The Textual bridge: a runner sink that only posts messages to the app.

The runner calls `handle` on the sweep's worker thread; `App.post_message` is thread-safe, so
the sweep never touches a widget nor the app's state. The app folds the events into a
`SweepState` on its own thread, then tells the screens on show (a `SweepChanged` message) and
they draw from that state. Every message carries `run`, the number the app gave the job when it
started it, so a late message of an earlier job never lands in a newer job's state.
"""

from __future__ import annotations

from typing import Any

from textual.app import App
from textual.message import Message

import procedures.engine.events as ev  # the contract: what procedures yield, front ends present


class SweepEvent(Message):
    """One procedure event, carried from the sweep thread to the app."""

    def __init__(self, event: ev.Event, run: int = 0) -> None:
        super().__init__()
        self.event = event
        self.run = run


class SweepEnded(Message):
    """The sweep worker returned. `error` is a sentence for the operator when the run could not
    start or broke off (a driver error, a plan outside the soft limits), else ""."""

    def __init__(self, outcome: str, points: int, error: str = "", note: str = "", result: Any = None,
                 run: int = 0) -> None:
        super().__init__()
        self.run = run
        self.outcome = outcome
        self.points = points
        self.error = error
        self.note = note  # e.g. a replay's comparison with its recording
        self.result = result  # what a job returned (a verification's JobOutcome), or None


class TuiBridge:
    """Runner sink (not critical: if posting ever fails the runner drops it, the sweep and
    its recording go on)."""

    critical = False

    def __init__(self, app: App, run: int = 0) -> None:
        self.app = app
        self.run = run

    def handle(self, event: ev.Event) -> None:
        self.app.post_message(SweepEvent(event, self.run))

    def close(self, outcome: str) -> None:
        pass
