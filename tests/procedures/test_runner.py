"""The one runner: sink failures, pause/resume, abort, and the procedure's cleanup always runs."""

from __future__ import annotations

import threading

import pytest

from procedures import events as ev
from procedures.control import Aborted, RunControl
from procedures.runner import CallbackSink, ListSink, run


def counting_procedure(n: int, control: RunControl, log: list[str]):
    """A stand-in procedure with the sweep's shape: check control, yield points, clean up."""
    yield ev.SweepStarted("s", (1,), n, {}, {})
    outcome = "completed"
    try:
        for i in range(n):
            control.check()
            log.append(f"move {i}")
            yield ev.PointMeasured({"index": i}, i + 1, n)
    except Aborted:
        outcome = "aborted"
    finally:
        log.append("drives stopped")
    yield ev.SweepFinished(outcome, len([x for x in log if x.startswith("move")]))


class Exploding:
    def __init__(self, critical: bool, after: int):
        self.critical, self.after, self.seen = critical, after, 0

    def handle(self, event):
        if isinstance(event, ev.PointMeasured):
            self.seen += 1
            if self.seen == self.after:
                raise OSError("disk full")

    def close(self, outcome):
        self.closed_with = outcome


def test_a_failing_display_sink_is_dropped_and_the_run_goes_on():
    log, events = [], ListSink()
    display = Exploding(critical=False, after=2)
    result = run(counting_procedure(5, RunControl(), log), [events, display])
    assert result.outcome == "completed" and result.points == 5
    assert display.seen == 2, "dropped after it failed"
    assert len(events.of(ev.PointMeasured)) == 5


def test_a_failing_recorder_stops_the_run_and_the_drives():
    log = []
    recorder = Exploding(critical=True, after=3)
    with pytest.raises(OSError, match="disk full"):
        run(counting_procedure(10, RunControl(), log), [recorder])
    assert log[-1] == "drives stopped"
    assert log.count("drives stopped") == 1 and len([x for x in log if x.startswith("move")]) == 3
    assert recorder.closed_with == "failed"


def test_the_procedure_is_not_resumed_before_every_sink_has_the_point():
    log = []
    order = []

    def sink(e):
        if isinstance(e, ev.PointMeasured):
            order.append(("recorded", e.record["index"], len([x for x in log if x.startswith("move")])))

    run(counting_procedure(3, RunControl(), log), [CallbackSink(sink)])
    # when point i is recorded, exactly i+1 moves have happened: the next move waits for the sink
    assert order == [("recorded", 0, 1), ("recorded", 1, 2), ("recorded", 2, 3)]


def test_pause_holds_the_procedure_between_points_and_resume_continues():
    control, log = RunControl(), []
    paused_at = {}
    resumed = threading.Event()

    def sink(e):
        if isinstance(e, ev.PointMeasured) and e.done == 2:
            control.pause()
        if isinstance(e, ev.Paused):
            paused_at["moves"] = len([x for x in log if x.startswith("move")])
            threading.Timer(0.05, lambda: (control.resume(), resumed.set())).start()

    events = ListSink()
    result = run(counting_procedure(4, control, log), [events, CallbackSink(sink)], control)
    assert result.outcome == "completed"
    assert paused_at["moves"] == 2 and resumed.is_set()
    kinds = [type(e).__name__ for e in events.events]
    assert kinds.index("Paused") == kinds.index("Resumed") - 1


def test_abort_calls_the_stop_callbacks_and_ends_aborted():
    control, log = RunControl(), []
    stops = []
    control.on_abort(lambda: stops.append("quick stop"))

    def sink(e):
        if isinstance(e, ev.PointMeasured) and e.done == 2:
            control.abort("operator")

    result = run(counting_procedure(6, control, log), [CallbackSink(sink)], control)
    assert result.outcome == "aborted" and result.points == 2
    assert stops == ["quick stop"] and log[-1] == "drives stopped"


def test_abort_while_paused_ends_the_run():
    control, log = RunControl(), []

    def sink(e):
        if isinstance(e, ev.PointMeasured) and e.done == 1:
            control.pause()
        if isinstance(e, ev.Paused):
            threading.Timer(0.05, control.abort).start()

    result = run(counting_procedure(5, control, log), [CallbackSink(sink)], control)
    assert result.outcome == "aborted" and result.points == 1
