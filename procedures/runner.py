"""The one runner every front end uses: pulls events from a procedure, feeds every sink.

- Sinks get each event in order. A *critical* sink (the recorder) that fails stops the run; a
  display sink that fails is dropped and logged, the run goes on.
- The procedure is only resumed after every sink has handled the event, so a point the
  recorder acknowledged is on disk before the next move.
- Pause: the runner stops pulling events (the procedure is suspended between points, so nothing
  moves) and emits `Paused`/`Resumed`. Abort: `RunControl.abort()` quick-stops the axes from the
  caller's thread; the procedure ends with outcome "aborted".
- Whatever happens (exception, Ctrl-C, a failed recorder), the `finally` closes the procedure,
  whose own `finally` stops and disables the drives, and then closes every sink.
"""

from __future__ import annotations

import logging
from typing import Callable, Iterable, Iterator, Protocol

from procedures import events as ev
from procedures.control import RunControl

log = logging.getLogger(__name__)


class Sink(Protocol):
    critical: bool

    def handle(self, event: ev.Event) -> None: ...
    def close(self, outcome: str) -> None: ...


class ListSink:
    """Collects events (tests, replay comparisons)."""

    critical = False

    def __init__(self) -> None:
        self.events: list[ev.Event] = []

    def handle(self, event: ev.Event) -> None:
        self.events.append(event)

    def close(self, outcome: str) -> None:
        pass

    def of(self, kind: type) -> list:
        return [e for e in self.events if isinstance(e, kind)]


class CallbackSink:
    """Calls a function per event (the TUI bridge posts messages from here)."""

    critical = False

    def __init__(self, fn: Callable[[ev.Event], None]) -> None:
        self.fn = fn

    def handle(self, event: ev.Event) -> None:
        self.fn(event)

    def close(self, outcome: str) -> None:
        pass


class RunResult:
    def __init__(self) -> None:
        self.outcome = "failed"
        self.reason = ""
        self.points = 0
        self.finished: ev.SweepFinished | None = None


def run(
    procedure: Iterator[ev.Event],
    sinks: Iterable[Sink],
    control: RunControl | None = None,
) -> RunResult:
    """Drive `procedure` to its end, feeding `sinks`. Returns the outcome."""
    control = control or RunControl()
    sinks = list(sinks)
    result = RunResult()

    def emit(event: ev.Event) -> None:
        for sink in list(sinks):
            try:
                sink.handle(event)
            except Exception as exc:
                if getattr(sink, "critical", False):
                    raise
                log.warning("display sink %r failed and was dropped: %s", sink, exc)
                sinks.remove(sink)

    try:
        for event in procedure:
            emit(event)
            if isinstance(event, ev.PointMeasured):
                result.points = event.done
            if isinstance(event, ev.SweepFinished):
                result.finished = event
                result.outcome, result.reason = event.outcome, event.reason
            if control.paused and not control.aborted:
                emit(ev.Paused())
                control.check_pause_only()
                emit(ev.Resumed())
    except KeyboardInterrupt:
        result.outcome, result.reason = "interrupted", "interrupted (Ctrl-C)"
        raise
    except Exception as exc:
        result.outcome, result.reason = "failed", f"{type(exc).__name__}: {exc}"
        raise
    finally:
        procedure_close = getattr(procedure, "close", None)
        if procedure_close is not None:
            procedure_close()  # runs the procedure's finally: drives stopped and disabled
        for sink in sinks:
            try:
                sink.close(result.outcome)
            except Exception:
                log.exception("sink %r failed to close", sink)
    return result
