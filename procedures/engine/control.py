"""Run control shared between a front end (any thread) and the running procedure.

Abort must stop motion even while the procedure is blocked inside a move: `abort()` therefore
calls the registered stop callbacks (the axes' quick stop) directly from the caller's thread.

Pause is handled in one place, `checkpoint()`: the procedure delegates to it (`yield from`)
before each motion step; when a pause was requested it yields `Paused`, blocks until resumed or
aborted, and yields `Resumed`. Every actual pause is therefore announced to the sinks, and nothing
moves in between. `check()` only raises `Aborted`; it never blocks.
"""

from __future__ import annotations

import logging
import threading
from typing import Callable, Iterator

from procedures.engine import events as ev

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
        self._closing = threading.Event()
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

    def wait_aborted(self, timeout_s: float) -> bool:
        """Block until an abort is asked for or `timeout_s` has passed; True if aborted."""
        return self._abort.wait(timeout_s)

    def on_abort(self, stop: Callable[[], None]) -> None:
        with self._lock:
            self._stops.append(stop)

    def check(self) -> None:
        """Raise `Aborted` if aborted (never blocks: pausing is `checkpoint()`'s)."""
        if self._abort.is_set():
            raise Aborted(self.reason)

    def checkpoint(self) -> Iterator[ev.Event]:
        """Where a procedure may pause: `yield from control.checkpoint()` before a motion step.

        Raises `Aborted` if aborted. If paused, yields `Paused`, blocks until resumed (or aborted:
        abort wakes a paused run), yields `Resumed`, and raises `Aborted` if the run was aborted
        meanwhile. The pause is decided here and only here, so a pause is never taken without
        its events, and a pause requested after this returned is taken at the next checkpoint.
        """
        self.check()
        if self._running.is_set():
            return
        yield ev.Paused()
        self._running.wait()
        yield ev.Resumed()
        self.check()

    # -- runner side -----------------------------------------------------------------------
    @property
    def closing(self) -> bool:
        """True once the run is finishing: its sweep has ended (the drives are stopped) or the
        runner is closing the procedure and the sinks. Nothing moves any more."""
        return self._closing.is_set()

    def begin_closing(self) -> None:
        """The runner is finishing: from here on an interrupt must not cut the cleanup short."""
        self._closing.set()
