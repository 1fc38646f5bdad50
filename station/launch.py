"""The `station` executable's entry point: the Ctrl-C handler first (station/startup_interrupt.py
says why), then the command line."""

import _signal  # the C module: `signal` imports enum, tens of milliseconds in which a Ctrl-C would be Python's

from station.startup_interrupt import record_interrupt


def main() -> int:
    _signal.signal(_signal.SIGINT, record_interrupt)
    from station.cli import main as cli_main

    return cli_main()
