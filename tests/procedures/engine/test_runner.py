"""The one runner: sink failures, pause/resume, abort, and the procedure's cleanup always runs."""

from __future__ import annotations

import threading

import pytest

from drivers.interfaces import DriveLimits, DriveState, DriveStatus, Environment, Reading
from procedures.engine import events as ev
from procedures.engine.control import Aborted, RunControl
from procedures.acquisition.plans import SweepPlan
from procedures.io.recording.reader import read_session
from procedures.io.recording.sink import RecorderSink
from procedures.engine.runner import CallbackSink, ListSink, run
from procedures.vocabulary import Outcome
from procedures.acquisition.sweep import sweep


def counting_procedure(n: int, control: RunControl, log: list[str]):
    """A stand-in procedure with the sweep's shape: check control, yield points, clean up."""
    yield ev.SweepStarted("s", (1,), n, {}, {})
    outcome = "completed"
    try:
        for i in range(n):
            yield from control.checkpoint()
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


def test_a_pause_requested_after_the_runner_looked_is_still_announced():
    """The race of issue 12: the runner used to look at `paused` after each event, and the
    procedure's own check blocked silently when the pause came in between. Now the pause is
    decided in one place (the checkpoint), which yields Paused before it waits."""
    control, log = RunControl(), []
    resumer: list[threading.Timer] = []

    def procedure():
        yield ev.SweepStarted("s", (1,), 3, {}, {})
        for i in range(3):
            if i == 1:  # the operator's pause lands here: after the runner handled point 0
                control.pause()
                resumer.append(threading.Timer(0.05, control.resume))
                resumer[0].start()
            yield from control.checkpoint()
            log.append(f"move {i}")
            yield ev.PointMeasured({"index": i}, i + 1, 3)
        yield ev.SweepFinished(Outcome.COMPLETED, 3)

    moves_at = {}

    def sink(e):
        if isinstance(e, (ev.Paused, ev.Resumed)):
            moves_at[type(e).__name__] = len(log)

    events = ListSink()
    result = run(procedure(), [events, CallbackSink(sink)], control)
    assert result.outcome is Outcome.COMPLETED
    kinds = [type(e).__name__ for e in events.events]
    assert kinds == ["SweepStarted", "PointMeasured", "Paused", "Resumed", "PointMeasured", "PointMeasured",
                     "SweepFinished"]
    assert moves_at == {"Paused": 1, "Resumed": 1}, "nothing moved while paused"


class _Axis:
    """A fake leg: moves at once, records every motion command."""

    def __init__(self, leg: int, moves: list, on_move=None):
        self.leg, self.moves, self.on_move, self.on = leg, moves, on_move, False

    def identity(self):
        return f"fake drive {self.leg}"

    def limits(self):
        return DriveLimits(-95.0, 95.0, 50.0, 500.0)

    def status(self, position_mm: float = 0.0):
        state = DriveState.OPERATION_ENABLED if self.on else DriveState.SWITCH_ON_DISABLED
        return DriveStatus(state, False, 0, False, True, position_mm, 0.0, 0.0, 0, False)

    def enable(self):
        self.on = True

    def disable(self):
        self.on = False

    def stop(self):
        pass

    def reset_fault(self):
        pass

    def move_to(self, target_mm, timeout_s=None):
        self.moves.append(target_mm)
        if self.on_move is not None:
            self.on_move(len(self.moves))
        return self.status(target_mm)


class _Laser:
    def identity(self):
        return "fake laser"

    def set_averaging(self, averaging_s):
        pass

    def zero(self, axis):
        pass

    def read(self, axis):
        return Reading(axis, 0.0, True, 90.0, 0.0)

    def environment(self):
        return Environment(20.0, 1013.0, 45.0, (20.0,))


class _Clock:
    t = 0.0

    def now(self):
        return self.t

    def sleep(self, dt_s):
        self.t += dt_s


def test_the_sweep_pauses_before_any_motion_and_announces_every_pause():
    """A pause requested during a move (from another thread, as the UI does) is taken before
    the next point moves, between Paused and Resumed; abort while paused ends the run."""
    control, moves = RunControl(), []
    plan = SweepPlan("t", (-10.0, 0.0, 10.0), cycles=1, legs=(1,), dwell_s=0.0, averaging_s=0.0, overrun_mm=1.0)

    def on_move(n):
        if n == 5:  # in the middle of a point (the reference takes 2 moves, a point 1 or 2)
            operator = threading.Thread(target=control.pause)
            operator.start()
            operator.join()

    moves_at = []

    def sink(e):
        if isinstance(e, ev.Paused):
            moves_at.append(len(moves))
            threading.Timer(0.05, control.abort, args=("operator",)).start()

    events = ListSink()
    result = run(sweep(plan, {1: _Axis(1, moves, on_move)}, _Laser(), _Clock(), control=control),
                 [events, CallbackSink(sink)], control)
    assert result.outcome is Outcome.ABORTED and result.reason == "operator"
    kinds = [type(e).__name__ for e in events.events]
    assert kinds.count("Paused") == 1 and kinds.index("Resumed") == kinds.index("Paused") + 1
    assert moves_at == [len(moves)], "no motion after the pause was announced"
    assert kinds[kinds.index("Paused") - 1] == "PointMeasured", "paused between points"


def test_ctrl_c_closes_the_recording_as_aborted_and_releases_its_lock(tmp_path):
    """A KeyboardInterrupt (a forced Ctrl-C) inside the run: the runner closes the recorder with
    Outcome.ABORTED (not a string the writer refuses), so the file is finished and unlocked."""
    out = tmp_path / "s.h5"
    control, log = RunControl(), []
    closed_with = []

    class Recorder(RecorderSink):
        def close(self, outcome):
            closed_with.append(outcome)
            super().close(outcome)

    def sink(e):
        if isinstance(e, ev.PointMeasured) and e.done == 3:
            raise KeyboardInterrupt

    def procedure():
        yield ev.SweepStarted("s", (1,), 5, {"kind": "test"}, {})
        for i in range(5):
            yield from control.checkpoint()
            log.append(f"move {i}")
            yield ev.PointMeasured({"index": i, "leg": 1, "run": 1, "direction": 1, "target_mm": float(i)}, i + 1, 5)
        yield ev.SweepFinished(Outcome.COMPLETED, 5)

    with pytest.raises(KeyboardInterrupt):
        run(procedure(), [Recorder(tmp_path / "s.h5"), CallbackSink(sink)], control)
    assert closed_with == [Outcome.ABORTED] and closed_with[0] is Outcome.ABORTED
    s = read_session(out)
    assert s.outcome == Outcome.ABORTED and len(s.points) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.h5"], "no lock file left"
