"""The one runner every front end uses: pulls events from a procedure, feeds every sink.

- Sinks get each event in order. A *critical* sink (the recorder) that fails stops the run; a
  display sink that fails is dropped and logged, the run goes on.
- The procedure is only resumed after every sink has handled the event, so a point the
  recorder acknowledged is on disk before the next move.
- Pause: the procedure pauses at its checkpoints (`yield from control.checkpoint()`, before each
  motion step), which yield `Paused`/`Resumed` around the wait; the runner passes them on like
  any event. Abort: `RunControl.abort()` quick-stops the axes from the caller's thread; the
  procedure ends with outcome "aborted".
- Whatever happens (exception, Ctrl-C, a failed recorder), the `finally` closes the procedure,
  whose own `finally` stops and disables the drives, and then closes every sink with the outcome:
  a KeyboardInterrupt (a forced Ctrl-C) closes them "aborted", any other exception "failed".
  `RunControl.begin_closing()` marks the finishing (from `SweepFinished` on, and the cleanup),
  so an interrupt handler can keep a further Ctrl-C from cutting it short (station/interrupt.py).
"""

from __future__ import annotations

import logging
from typing import Callable, Iterable, Iterator, Protocol

from procedures.engine import events as ev
from procedures.engine.control import RunControl
from procedures.vocabulary import Outcome

log = logging.getLogger(__name__)


class Sink(Protocol):
    critical: bool

    def handle(self, event: ev.Event) -> None: ...
    def close(self, outcome: Outcome) -> None: ...


class ListSink:
    """Collects events (tests, replay comparisons)."""

    critical = False

    def __init__(self) -> None:
        self.events: list[ev.Event] = []

    def handle(self, event: ev.Event) -> None:
        self.events.append(event)

    def close(self, outcome: Outcome) -> None:
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

    def close(self, outcome: Outcome) -> None:
        pass


class RunResult:
    def __init__(self) -> None:
        self.outcome: Outcome = Outcome.FAILED
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
            if isinstance(event, ev.SweepFinished):
                control.begin_closing()  # the drives are stopped; what is left is finishing the files
            emit(event)
            if isinstance(event, ev.PointMeasured):
                result.points = event.done
            if isinstance(event, ev.SweepFinished):
                result.finished = event
                result.outcome, result.reason = Outcome(event.outcome), event.reason
        control.begin_closing()
    except KeyboardInterrupt:
        # Ctrl-C that was not turned into an abort, or a second one that forces the stop: the
        # operator stopped the run, and the recording is finished as aborted like any abort
        control.begin_closing()
        result.outcome = Outcome.ABORTED
        result.reason = "interrupted (Ctrl-C twice)" if control.aborted else "interrupted (Ctrl-C)"
        raise
    except Exception as exc:
        control.begin_closing()
        result.outcome, result.reason = Outcome.FAILED, f"{type(exc).__name__}: {exc}"
        raise
    finally:
        control.begin_closing()
        procedure_close = getattr(procedure, "close", None)
        try:
            if procedure_close is not None:
                procedure_close()  # runs the procedure's finally: drives stopped and disabled
        finally:
            _close_sinks(sinks, result.outcome)
    return result


def _close_sinks(sinks: list[Sink], outcome: Outcome) -> None:
    """Close every sink with `outcome`; one failing (even interrupted) does not keep the others
    open. A KeyboardInterrupt is re-raised once all are closed."""
    interrupted: BaseException | None = None
    for sink in sinks:
        try:
            sink.close(outcome)
        except Exception:
            log.exception("sink %r failed to close", sink)
        except KeyboardInterrupt as exc:
            interrupted = exc
    if interrupted is not None:
        raise interrupted
