"""The `station` executable's entry point: the Ctrl-C handler first (station/startup_interrupt.py
says why), then the command line."""

import _signal  # the C module: `signal` imports enum, tens of milliseconds in which a Ctrl-C would be Python's

_early = False


def _record_early(signum, frame) -> None:
    """SIGINT while station.startup_interrupt itself loads: remembered, handed on to it."""
    global _early
    _early = True


def main() -> int:
    _signal.signal(_signal.SIGINT, _record_early)  # before any further module loads
    from station import startup_interrupt

    _signal.signal(_signal.SIGINT, startup_interrupt.record_interrupt)
    if _early:
        startup_interrupt.record_interrupt(_signal.SIGINT, None)
    from station.cli import main as cli_main

    return cli_main()
