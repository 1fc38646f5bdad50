"""station.interrupt: Ctrl-C during a run, through the RunControl of procedures.engine.control (the
runner's side of it: tests/procedures/engine/test_runner.py)."""

from __future__ import annotations

import signal

import pytest

from procedures.engine.control import RunControl
from station.interrupt import abort_on_sigint


def test_a_second_ctrl_c_while_the_recording_closes_is_not_raised(tmp_path):
    """station.interrupt: the first Ctrl-C aborts, a second raises KeyboardInterrupt once, and
    none is raised once the runner is closing (it would cut the file's finishing short)."""
    control = RunControl()
    with abort_on_sigint(control):
        signal.raise_signal(signal.SIGINT)
        assert control.aborted and control.reason == "interrupted (Ctrl-C)"
        control.begin_closing()
        signal.raise_signal(signal.SIGINT)  # ignored: closing
    control = RunControl()
    with abort_on_sigint(control):
        signal.raise_signal(signal.SIGINT)
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)
        signal.raise_signal(signal.SIGINT)  # once forced, no more
