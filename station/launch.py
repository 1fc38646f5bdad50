"""The `station` executable's entry point.

A Ctrl-C while Python is still loading the command line would print a traceback (the first
tenths of a second of every command). Until station.cli.main takes over, a Ctrl-C ends the
program at once with one line and exit code 130, as any command does when interrupted.
"""

from __future__ import annotations

import os
import signal


def _interrupted_while_loading(signum, frame) -> None:
    try:
        os.write(2, b"station: interrupted\n")
    finally:
        os._exit(130)


def main() -> int:
    signal.signal(signal.SIGINT, _interrupted_while_loading)
    from station.cli import main as cli_main

    return cli_main()
