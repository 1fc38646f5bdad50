import io

from procedures.engine import events as ev
from station.progress import ConsoleProgress, fmt_duration


class Tty(io.StringIO):
    def isatty(self):
        return True


def _points(sink, n):
    for i in range(1, n + 1):
        sink.handle(ev.PointMeasured({"leg": 1, "run": 1, "target_mm": 0.0, "error_um": 0.1}, i, n))
    sink.handle(ev.SweepFinished("completed", n))
    sink.close("completed")


def test_a_pipe_gets_one_line_per_tenth_and_no_carriage_returns():
    out = io.StringIO()
    _points(ConsoleProgress(out), 200)
    text = out.getvalue()
    assert "\r" not in text
    progress = [line for line in text.splitlines() if " points (" in line]
    assert len(progress) == 10 and progress[-1].startswith("200/200 points (100%)")
    assert text.rstrip().endswith("sweep completed: 200 points")


def test_a_terminal_gets_a_redrawn_bar():
    out = Tty()
    _points(ConsoleProgress(out), 20)
    assert "\r[" in out.getvalue() and "20/20 100.0%" in out.getvalue()


def test_durations():
    assert fmt_duration(None) == "--:--" and fmt_duration(75) == "01:15" and fmt_duration(3725) == "1:02:05"
