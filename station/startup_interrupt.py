"""What a Ctrl-C during start-up does: recorded while the command's modules load, acted on once
they are.

A Ctrl-C while Python is still loading modules must neither print a traceback nor be lost. A
KeyboardInterrupt raised at that moment can be lost: when the signal lands while a finaliser
or a callback runs (`__del__`, a weakref callback), Python prints "Exception ignored" and goes
on, and the sweep runs on. So until the command's modules are loaded, the handler only records
the interrupt (`record_interrupt`); station.cli checks it once they are, and ends the command
with one line and exit code 130. From then on a Ctrl-C raises KeyboardInterrupt and is recorded
too (`interrupt_now`), and `station.interrupt.abort_on_sigint` aborts its run at once on entry
when one came before it (one raised, then lost, on the way there).

A module of its own, below both the entry point (station/launch.py, which installs the handler
first) and station/cli.py (which acts on it), so neither imports the other's importer.
"""

_interrupted = False


def record_interrupt(signum, frame) -> None:
    """SIGINT while the command's modules load: remembered, acted on once they are loaded."""
    global _interrupted
    _interrupted = True


def interrupt_now(signum, frame) -> None:
    """SIGINT once loaded: remembered, and a KeyboardInterrupt at once."""
    global _interrupted
    _interrupted = True
    raise KeyboardInterrupt


def interrupted() -> bool:
    """A Ctrl-C came since the command started (and was not yet acted on by `forget`)."""
    return _interrupted


def forget() -> None:
    """The command has ended: a Ctrl-C of this one does not count for the next (in-process runs)."""
    global _interrupted
    _interrupted = False
