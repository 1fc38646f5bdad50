"""Ctrl-C during a run: the first one aborts cleanly (motion stopped, file finished and
resumable), a second one interrupts at once.

A KeyboardInterrupt raised at an arbitrary point can land inside h5py's cleanup and be lost, so
the signal is turned into `RunControl.abort()` instead and the procedure ends normally. The
second Ctrl-C does raise KeyboardInterrupt (to get out of a blocking call), once: the runner then
closes the procedure and finishes the recording as "aborted". Once the runner is closing
(`RunControl.closing`), or after that one forced interrupt, a further Ctrl-C only says what is
going on, so it cannot cut the file's finishing short and leave it open and locked.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading

from procedures.engine.control import RunControl
from station import startup_interrupt

REASON = "interrupted (Ctrl-C)"


def _say(text: str) -> None:
    # the handler may interrupt a write to stderr: a reentrant write must not raise into the run
    try:
        print(text, file=sys.stderr, flush=True)
    except (OSError, RuntimeError, ValueError):
        pass


@contextlib.contextmanager
def abort_on_sigint(control: RunControl):
    if threading.current_thread() is not threading.main_thread():
        yield control
        return
    previous = signal.getsignal(signal.SIGINT)
    forced = False

    def handler(signum, frame):
        nonlocal forced
        if not control.aborted:
            _say("\nCtrl-C: stopping the motion and closing the recording (Ctrl-C again to force)")
            control.abort(REASON)
            return
        if forced or control.closing:
            _say("\nCtrl-C: closing the recording, one moment")
            return
        forced = True
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)
    if startup_interrupt.interrupted() and not control.aborted:
        # a Ctrl-C came on the way here (after the modules loaded) and its KeyboardInterrupt was
        # lost (it landed in a finaliser, say): abort now, before anything moves
        handler(signal.SIGINT, None)
    try:
        yield control
    finally:
        signal.signal(signal.SIGINT, previous)
