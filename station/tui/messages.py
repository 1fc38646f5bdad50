"""Messages posted from worker threads to the app (never widget calls from a thread)."""

from __future__ import annotations

from typing import Any

from textual.message import Message


class RigConnected(Message):
    def __init__(self, rig: Any) -> None:
        super().__init__()
        self.rig = rig


class RigConnectFailed(Message):
    def __init__(self, error: str) -> None:
        super().__init__()
        self.error = error


class RigActionDone(Message):
    """A rig action (enable, home, reset, stop) finished; `error` is "" on success."""

    def __init__(self, action: str, legs: tuple[int, ...], error: str = "") -> None:
        super().__init__()
        self.action = action
        self.legs = legs
        self.error = error


class Notice(Message):
    """A notification to show (severity: information / warning / error)."""

    def __init__(self, text: str, severity: str = "information", title: str = "") -> None:
        super().__init__()
        self.text = text
        self.severity = severity
        self.title = title
