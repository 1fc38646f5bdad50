"""`station` command line: discovers sub-commands in station.commands and runs one.

Errors a user can act on (bad input, unreachable devices) are printed as one clear line on
stderr with exit code 2; no traceback reaches a technician. Set STATION_DEBUG=1 to see one.
"""

from __future__ import annotations

import os

# The fits solve many small least-squares problems: BLAS threads only contend for the two cores
# of a bench PC. Must be set before numpy loads; a user's own setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import ast
import functools
import importlib
import logging
import pkgutil
import signal
import sys
import threading
from pathlib import Path

from drivers.errors import DriverError
from procedures.vocabulary import InputError
from station import __version__, startup_interrupt


@functools.cache
def _command_specs() -> dict[str, dict[str, str]]:
    """NAME/HELP/DESCRIPTION of every command module, read from their source without importing
    them, so `station X` imports only command X (the TUI, scipy and matplotlib stay unloaded
    for a quick `station sweep`)."""
    import station.commands as pkg

    specs: dict[str, dict[str, str]] = {}
    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda i: i.name):
        if info.name.startswith("_"):
            continue
        path = Path(pkg.__path__[0]) / f"{info.name}.py"
        values: dict[str, str] = {"module": info.name}
        source = path.read_text()
        # NAME/HELP/DESCRIPTION stand above the first function: parsing only that part halves the
        # time every command spends on this (the whole module when the part does not parse alone)
        head = source.split("\ndef ", 1)[0]
        try:
            tree = ast.parse(head)
        except SyntaxError:
            tree = ast.parse(source)
        for node in tree.body:
            if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
                key = node.targets[0].id
                if key in ("NAME", "HELP", "DESCRIPTION") and isinstance(node.value, ast.Constant):
                    values[key] = str(node.value.value)
        if "NAME" in values:
            specs[values["NAME"]] = values
    return specs


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a refusal is one line (`station CMD: error: ...; see station CMD --help`) with
    exit 2, not the usage block followed by the error: the line that says what to do is the one a
    technician reads, and scripts grep one line (issue 31)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}; see `{self.prog} --help`\n")


def _os_error_line(exc: OSError) -> str:
    """An OSError as one line naming the path and what to do (not "[Errno 13] ...", not a bare
    "runs: permission denied" that leaves a user guessing which folder and why)."""
    path = exc.filename or ""
    why = (exc.strerror or str(exc)).lower()
    if isinstance(exc, PermissionError) or exc.errno == 30:  # EACCES/EPERM, EROFS
        where = os.path.abspath(path) if path else "a file"
        try:
            import pwd

            user = pwd.getpwuid(os.getuid()).pw_name
        except (ImportError, KeyError):
            user = str(os.getuid())
        return (f"{where}: {why} (user {user}); run the station from a folder you can write (its recordings, "
                "audit log and catalog go to recordings_dir, default runs/ in the current folder), give --config "
                "with [station] recordings_dir = a folder you can write, or fix the permissions")
    return f"{path}: {why}" if path else why


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The full parser lists every command; arguments are added for `command` only (or for
    all when None)."""
    parser = OneLineParser(
        prog="station",
        description="Calibration station for the ball-screw legs of Gough-Stewart platforms.",
    )
    parser.add_argument("--version", action="version", version=f"station {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, spec in _command_specs().items():
        help_text = spec.get("HELP", "")
        p = sub.add_parser(name, help=help_text, description=spec.get("DESCRIPTION", help_text))
        if command is None or command == name:
            mod = importlib.import_module(f"station.commands.{spec['module']}")
            mod.add_arguments(p)
            p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one command; its exit code. Ctrl-C at any moment, also while the command's modules
    load (the first fraction of a second), ends with one line and exit code 130."""
    if threading.current_thread() is threading.main_thread():
        # while the command's modules load, a Ctrl-C is only recorded (station/startup_interrupt.py says why)
        signal.signal(signal.SIGINT, startup_interrupt.record_interrupt)
    try:
        try:
            return _main(argv)
        except KeyboardInterrupt:
            print("station: interrupted", file=sys.stderr)
            return 130
        finally:
            if threading.current_thread() is threading.main_thread():
                # the command has ended: a Ctrl-C from now on (a second one while the first's
                # abort closes the recording) only counts, it cannot raise out of here
                signal.signal(signal.SIGINT, startup_interrupt.record_interrupt)
            startup_interrupt.forget()
    except KeyboardInterrupt:  # one that landed in the lines just above
        startup_interrupt.forget()
        return 130


def _main(argv: list[str] | None) -> int:
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # frame dumps are not for users
    argv = sys.argv[1:] if argv is None else argv
    specs = _command_specs()
    if not argv:
        argv = ["ui"] if "ui" in specs else ["--help"]
    command = argv[0] if argv[0] in specs else None
    parser = build_parser(command) if command else build_parser("")
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # a refused argument (2) or --help (0): an exit code like any other
        return exc.code if isinstance(exc.code, int) else 2
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    if threading.current_thread() is threading.main_thread():
        # loaded: a Ctrl-C that came meanwhile ends the command here; from now on one raises
        signal.signal(signal.SIGINT, startup_interrupt.interrupt_now)
    if startup_interrupt.interrupted():
        raise KeyboardInterrupt
    try:
        return int(args._run(args) or 0)
    except (InputError, DriverError, FileNotFoundError, PermissionError, IsADirectoryError) as exc:
        if os.environ.get("STATION_DEBUG"):
            raise
        message = str(exc)
        if isinstance(exc, OSError) and exc.filename and exc.strerror:
            message = _os_error_line(exc)  # not "[Errno 2] ..."
        message = "; ".join(part.strip() for part in message.splitlines() if part.strip())  # one line
        print(f"station {args.command}: error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"station {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into `head` and the like: not an error
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except OSError as exc:  # a read-only file system, a full disk: one line naming the path, exit 2
        if os.environ.get("STATION_DEBUG"):
            raise
        print(f"station {args.command}: error: {_os_error_line(exc)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
