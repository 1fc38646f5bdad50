"""`station` command line: discovers sub-commands in station.commands and runs one.

Errors a user can act on (bad input, unreachable devices) are printed as one clear line on
stderr with exit code 2; no traceback reaches a technician. Set STATION_DEBUG=1 to see one.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import pkgutil
import sys

from drivers.errors import DriverError
from procedures.errors import InputError
from station import __version__


def _command_modules():
    import station.commands as pkg

    mods = []
    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda i: i.name):
        if info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"station.commands.{info.name}")
        if hasattr(mod, "NAME") and hasattr(mod, "run"):
            mods.append(mod)
    return mods


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="station",
        description="Calibration station for the ball-screw legs of Gough-Stewart platforms.",
    )
    parser.add_argument("--version", action="version", version=f"station {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in _command_modules():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP))
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # frame dumps are not for users
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser()
    if not argv:
        argv = ["ui"] if "ui" in parser._subparsers._group_actions[0].choices else ["--help"]  # type: ignore[union-attr]
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    try:
        return int(args._run(args) or 0)
    except (InputError, DriverError, FileNotFoundError, PermissionError, IsADirectoryError) as exc:
        if os.environ.get("STATION_DEBUG"):
            raise
        print(f"station {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"station {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
