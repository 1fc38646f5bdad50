"""Ctrl-C during a run: the first one aborts cleanly (motion stopped, file finished and
resumable), a second one interrupts at once.

A KeyboardInterrupt raised at an arbitrary point can land inside h5py's cleanup and be lost, so
the signal is turned into `RunControl.abort()` instead and the procedure ends normally.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading

from procedures.control import RunControl


@contextlib.contextmanager
def abort_on_sigint(control: RunControl):
    if threading.current_thread() is not threading.main_thread():
        yield control
        return
    previous = signal.getsignal(signal.SIGINT)

    def handler(signum, frame):
        if control.aborted:
            raise KeyboardInterrupt
        print("\nCtrl-C: stopping the motion and closing the recording (Ctrl-C again to force)",
              file=sys.stderr, flush=True)
        control.abort("interrupted (Ctrl-C)")

    signal.signal(signal.SIGINT, handler)
    try:
        yield control
    finally:
        signal.signal(signal.SIGINT, previous)
