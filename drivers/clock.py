"""Clocks: the real one, and a virtual one so a six-hour sweep runs in seconds.

`time_scale` is real seconds per virtual second: 1 = real time, 0.01 = 100x faster,
0 = no waiting at all (virtual time only advances through `sleep`/`advance`).
"""

from __future__ import annotations

import threading
import time


class SystemClock:
    """Wall-clock time (monotonic), for real hardware."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, dt_s: float) -> None:
        if dt_s > 0:
            time.sleep(dt_s)


class VirtualClock:
    """A clock whose seconds last `time_scale` real seconds. Thread-safe.

    Virtual time advances with real time (divided by the scale) when the scale is > 0, and
    by exactly `dt_s` on every `sleep(dt_s)`/`advance(dt_s)` at scale 0.
    """

    def __init__(self, time_scale: float = 0.0, start_s: float = 0.0):
        if time_scale < 0:
            raise ValueError(f"time scale must be >= 0, got {time_scale}")
        self.time_scale = float(time_scale)
        self._lock = threading.Lock()
        self._offset_s = float(start_s)
        self._real0 = time.monotonic()
        self._events: list[tuple] = []  # (next_due, on_due): see add_events
        self._reads = 0  # now() calls at time scale 0
        self._last_read: dict[int, int] = {}  # thread ident -> the number of its latest now() call

    def add_events(self, next_due, on_due) -> None:
        """A source of instants the clock must stop at (time scale 0): while advancing, the clock
        stops at `next_due()` (the source's next instant, or None) whenever it lies within the
        jump, and calls `on_due(t)` there, in the advancing thread, before going on (every source due
        at that instant, in the order added). A simulated
        instrument that streams (drivers/sim/linef1_server.py) samples the plant there, so a
        move made within one request still yields samples along its path at their own times."""
        self._events.append((next_due, on_due))

    def now(self) -> float:
        if self.time_scale == 0:
            # who asked (read_since): a simulated instrument waits for its client's time stamp
            self._reads += 1
            self._last_read[threading.get_ident()] = self._reads
            return self._offset_s  # one attribute read, atomic: no lock (asked several times a point)
        with self._lock:
            return self._offset_s + (time.monotonic() - self._real0) / self.time_scale

    def reads(self) -> int:
        """The count of `now()` calls so far (time scale 0): a mark for `read_since`."""
        return self._reads

    def read_since(self, mark: int, exclude: set[int]) -> bool:
        """Whether a thread not in `exclude` (thread idents) asked the time since `mark` (time
        scale 0): the simulated µLine-F1 waits, the clock standing at a frame's instant, until
        its client has time-stamped what it wrote (drivers/sim/linef1_server.py)."""
        return any(n > mark and ident not in exclude for ident, n in list(self._last_read.items()))

    def read_by(self, mark: int, ident: int) -> bool:
        """Whether thread `ident` asked the time since `mark` (time scale 0): the simulated
        µLine-F1 waits for its client's reader to stamp what it wrote; another thread's reads
        (the drive's server answering a late request) must not count."""
        return self._last_read.get(ident, 0) > mark

    def advance(self, dt_s: float) -> None:
        """Jump virtual time forward by `dt_s` without waiting (any scale); at scale 0 stopping
        at every event instant within the jump (`add_events`)."""
        if dt_s <= 0:
            return
        if self.time_scale != 0 or not self._events:
            with self._lock:
                self._offset_s += dt_s
            return
        target = self._offset_s + dt_s
        while True:
            due = [(t, on_due) for next_due, on_due in self._events if (t := next_due()) is not None]
            t = min(d[0] for d in due) if due else None
            with self._lock:
                if t is None or not self._offset_s < t <= target:
                    self._offset_s = max(self._offset_s, target)
                    return
                self._offset_s = t
            # every source due at this instant, in the order added: one that asks again once the
            # clock stands here would find its instant no longer ahead, and be skipped
            for t_due, on_due in due:
                if t_due == t:
                    on_due(t)  # outside the clock's lock: it may read the clock

    def sleep(self, dt_s: float) -> None:
        if dt_s <= 0:
            return
        if self.time_scale == 0:
            self.advance(dt_s)
        else:
            time.sleep(dt_s * self.time_scale)
