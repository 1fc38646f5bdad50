"""Run control shared between a front end (any thread) and the running procedure.

Abort must stop motion even while the procedure is blocked inside a move: `abort()` therefore
calls the registered stop callbacks (the axes' quick stop) directly from the caller's thread.
"""

from __future__ import annotations

import logging
import threading
from typing import Callable

log = logging.getLogger(__name__)


class Aborted(Exception):
    """Raised inside a procedure when the operator aborted the run."""


class RunControl:
    def __init__(self) -> None:
        self._abort = threading.Event()
        self._running = threading.Event()
        self._running.set()  # not paused
        self._stops: list[Callable[[], None]] = []
        self._lock = threading.Lock()
        self.reason = ""

    # -- front end side ------------------------------------------------------------------
    def abort(self, reason: str = "aborted by the operator") -> None:
        with self._lock:
            if not self._abort.is_set():
                self.reason = reason
            self._abort.set()
            stops = list(self._stops)
        self._running.set()  # wake a paused run so it can end
        for stop in stops:
            try:
                stop()
            except Exception:  # a dead link must not keep the other axes moving
                log.exception("stop callback failed during abort")

    def pause(self) -> None:
        self._running.clear()

    def resume(self) -> None:
        self._running.set()

    # -- procedure side ------------------------------------------------------------------
    @property
    def aborted(self) -> bool:
        return self._abort.is_set()

    @property
    def paused(self) -> bool:
        return not self._running.is_set()

    def on_abort(self, stop: Callable[[], None]) -> None:
        with self._lock:
            self._stops.append(stop)

    def check_pause_only(self) -> None:
        """Block while paused (returns at once when aborted, so the run can end)."""
        self._running.wait()

    def check(self) -> None:
        """Raise `Aborted` if aborted; block while paused."""
        if self._abort.is_set():
            raise Aborted(self.reason)
        if not self._running.is_set():
            self._running.wait()
            if self._abort.is_set():
                raise Aborted(self.reason)
