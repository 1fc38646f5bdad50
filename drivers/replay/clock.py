"""The replay clock: the recording's time, played back at a chosen speed.

Time comes from the recording. Whenever a replay device answers with a recorded point (or
raises a recorded fault) the clock is *set* to the time recorded for it, so a procedure that
stamps `clock.now() - t_start` (with t_start = 0) gets the recorded `time_s` bit for bit. In
between, the clock advances by the procedure's own sleeps and the drives' move times, like the
simulated rig's virtual clock at time scale 0. A position query that the recording does not
answer afresh (the same point read again, the client's own retries into a replayed silence or
line noise) leaves it where it is: the recorded time of a fault is the time the client gave up.

Speed: `speed=None` runs as fast as possible; `speed=1` replays in real time; `speed=10` ten
times faster. The waiting happens only in `sleep()` calls of the procedure's thread (the
sweep sleeps for the dwell at every point, also when the dwell is 0), never inside a device
request, where a wait would look like a silent device to the client. The waiting keeps
`wall - wall0 = (now - t0) / speed` from an anchor taken at the first sleep; the anchor is
taken again when the recorded time goes backwards (a resumed session starts its clock again)
and when the replay has fallen behind (after a pause of the run), so it never rushes.

Nothing the replay records may depend on the wall clock, so nothing may depend on how busy the
machine is. The wall-clock waits left are the clients' reply timeouts, and on a replay none of
them may fire for a request the replay devices answer: a timed-out request is asked again (a
question the recording does not hold: the same reading served twice, or the next recorded fault
taken for it) or becomes a fault the recording does not have. So on a replay both timeouts are
long (station.services.wiring.open_replay_rig), and the interferometer client measures its timeout on a
`TimeoutClock`: the system's monotonic clock, jumping past any reply timeout whenever the
replay instrument replays a recorded silence, so a recorded time-out still ends at once.
"""

from __future__ import annotations

import math
import threading
import time

LATE_REANCHOR_S = 0.5
"""Pacing lagging the wall clock by more than this (seconds) is forgotten, not caught up."""


class ReplayClock:
    """Implements drivers.interfaces.Clock for the procedure; `device_clock()` is the view the
    replay servers use (advances without waiting). Thread-safe."""

    def __init__(self, speed: float | None = None, start_s: float = 0.0):
        if speed is not None and not (isinstance(speed, (int, float)) and math.isfinite(speed) and speed > 0):
            raise ValueError(f"replay speed must be a positive number (1 = real time) or None (as fast as possible), got {speed!r}")
        self.speed = None if speed is None else float(speed)
        self._lock = threading.Lock()
        self._t = float(start_s)
        self._anchor: tuple[float, float] | None = None  # (clock time, wall time) of the pacing anchor
        self._cancelled = threading.Event()
        self.waited_s = 0.0  # real seconds spent pacing (statistics)

    def now(self) -> float:
        return self._t  # one attribute read, atomic: no lock (asked several times a point)

    def advance(self, dt_s: float) -> None:
        """Move the clock forward by `dt_s` seconds without waiting."""
        if dt_s > 0:
            with self._lock:
                self._t += dt_s

    def set_recorded(self, t_s: float) -> None:
        """Set the clock to a recorded time (seconds since the session start). NaN is ignored."""
        if not math.isfinite(t_s):
            return
        with self._lock:
            if t_s < self._t:
                self._anchor = None  # time went back (a resumed session): pace from here
            self._t = float(t_s)

    def sleep(self, dt_s: float) -> None:
        """Advance by `dt_s`, then wait until the wall clock has caught up at the chosen speed."""
        self.advance(dt_s)
        if self.speed is None or self._cancelled.is_set():
            return
        with self._lock:
            now_wall = time.monotonic()
            if self._anchor is None:
                self._anchor = (self._t, now_wall)
                return
            t0, wall0 = self._anchor
            wait_s = wall0 + (self._t - t0) / self.speed - now_wall
            if wait_s < -LATE_REANCHOR_S:
                # behind by more than a moment (a pause, a busy machine): carry on at the chosen
                # speed from here instead of rushing to catch up
                self._anchor = (self._t, now_wall)
        if wait_s > 0:
            self._cancelled.wait(wait_s)
            self.waited_s += wait_s

    def cancel_waits(self) -> None:
        """End every present and future wait at once (the run is being aborted)."""
        self._cancelled.set()

    def device_clock(self) -> "DeviceClock":
        return DeviceClock(self)


class DeviceClock:
    """The replay clock as the servers see it: `sleep` advances without waiting, and
    `time_scale` 0 makes the drive complete each move within the request that commands it."""

    time_scale = 0.0

    def __init__(self, clock: ReplayClock):
        self._clock = clock

    def now(self) -> float:
        return self._clock.now()

    def sleep(self, dt_s: float) -> None:
        self._clock.advance(dt_s)


SILENCE_S = 3600.0
"""How far a replayed silence moves the `TimeoutClock` on: past any client reply timeout."""


class TimeoutClock:
    """The clock the interferometer client measures its reply timeouts on during a replay
    (`SerialInterferometer(clock=...)`): the system's monotonic clock, moved on by `SILENCE_S`
    by `silence()`, which the replay instrument calls when it replays a recorded silence (it
    then answers nothing). The client takes each deadline before sending its command, so the
    silence it provokes puts the deadline behind at once: a recorded time-out costs one read
    poll (20 ms) per attempt, not the timeout. Thread-safe."""

    def __init__(self):
        self._lock = threading.Lock()
        self._skipped_s = 0.0
        self.silences = 0  # replayed silences (statistics)

    def now(self) -> float:
        return time.monotonic() + self._skipped_s  # one attribute read: no lock needed

    def sleep(self, dt_s: float) -> None:
        if dt_s > 0:
            time.sleep(dt_s)

    def silence(self) -> None:
        """A query is left unanswered (a recorded time-out): end the client's wait for it now."""
        with self._lock:
            self._skipped_s += SILENCE_S
            self.silences += 1
