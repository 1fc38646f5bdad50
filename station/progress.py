"""Progress for the front ends: ETA estimation and the console progress bar sink."""

from __future__ import annotations

import sys
import time
from typing import TextIO

from procedures.engine import events as ev


class Eta:
    """Remaining time from the wall-clock rate of the points measured in this run."""

    def __init__(self) -> None:
        self.t0: float | None = None
        self.done0 = 0

    def update(self, done: int, total: int) -> tuple[float, float | None]:
        now = time.monotonic()
        if self.t0 is None:
            self.t0, self.done0 = now, done - 1
        elapsed = now - self.t0
        rate_done = done - self.done0
        if rate_done <= 0 or elapsed <= 0:
            return elapsed, None
        return elapsed, (total - done) * elapsed / rate_done


def fmt_duration(seconds: float | None) -> str:
    if seconds is None:
        return "--:--"
    seconds = int(round(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m:02d}:{s:02d}"


class ConsoleProgress:
    """A one-line progress bar with ETA on stderr; faults and messages on their own lines."""

    critical = False

    def __init__(self, stream: TextIO | None = None, width: int = 30) -> None:
        self.stream = stream or sys.stderr
        self.width = width
        # A log file or pipe gets a plain line every 10 % instead of a redrawn bar.
        self.redraw = bool(getattr(self.stream, "isatty", lambda: False)())
        self._next_decile = 1
        self.eta = Eta()
        self._last_draw = 0.0
        self._line_open = False

    def _line(self, text: str) -> None:
        if self._line_open:
            self.stream.write("\n")
            self._line_open = False
        self.stream.write(text + "\n")
        self.stream.flush()

    def handle(self, event: ev.Event) -> None:
        if isinstance(event, ev.SweepStarted):
            extra = f", resuming after {event.resumed_points} recorded points" if event.resumed_points else ""
            self._line(f"sweep {event.session_id}: legs {list(event.legs)}, {event.total_points} points{extra}")
        elif isinstance(event, ev.LegStarted):
            self._line(f"leg {event.leg}: enabled, zeroed at mid-stroke")
        elif isinstance(event, ev.PointMeasured):
            elapsed, eta = self.eta.update(event.done, event.total)
            if not self.redraw:
                if event.done * 10 >= self._next_decile * event.total:
                    self._next_decile = event.done * 10 // max(event.total, 1) + 1
                    self._line(f"{event.done}/{event.total} points ({event.done / max(event.total, 1):.0%}), "
                               f"ETA {fmt_duration(eta)}")
                return
            now = time.monotonic()
            if now - self._last_draw < 0.1 and event.done < event.total:
                return
            self._last_draw = now
            frac = event.done / max(event.total, 1)
            bar = "#" * int(frac * self.width)
            r = event.record
            self.stream.write(
                f"\r[{bar:<{self.width}}] {event.done}/{event.total} {frac:6.1%}  ETA {fmt_duration(eta)}  "
                f"leg {r['leg']} run {r['run']:>2} {r['target_mm']:+8.3f} mm {r['error_um']:+7.3f} um "
            )
            self.stream.flush()
            self._line_open = True
        elif isinstance(event, ev.Fault):
            what = "gave up" if event.gave_up else f"attempt {event.attempt}, retrying"
            self._line(f"fault at leg {event.leg} run {event.run} target {event.target_mm:+.4f} mm: {event.kind}: {event.message} ({what})")
        elif isinstance(event, ev.Paused):
            self._line("paused")
        elif isinstance(event, ev.Resumed):
            self._line("resumed")
        elif isinstance(event, ev.Message):
            self._line(f"{event.level}: {event.text}")
        elif isinstance(event, ev.SweepFinished):
            self._line(f"sweep {event.outcome}: {event.points} points" + (f" ({event.reason})" if event.reason else ""))

    def close(self, outcome: str) -> None:
        if self._line_open:
            self.stream.write("\n")
            self.stream.flush()
            self._line_open = False
