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

    def now(self) -> float:
        if self.time_scale == 0:
            return self._offset_s  # one attribute read, atomic: no lock (asked several times a point)
        with self._lock:
            return self._offset_s + (time.monotonic() - self._real0) / self.time_scale

    def advance(self, dt_s: float) -> None:
        """Jump virtual time forward by `dt_s` without waiting (any scale)."""
        if dt_s > 0:
            with self._lock:
                self._offset_s += dt_s

    def sleep(self, dt_s: float) -> None:
        if dt_s <= 0:
            return
        if self.time_scale == 0:
            self.advance(dt_s)
        else:
            time.sleep(dt_s * self.time_scale)
