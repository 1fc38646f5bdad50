"""Turn exceptions into one sentence an operator can act on (shown as a notification)."""

from __future__ import annotations

import logging

from station.services.devices import DriverError

log = logging.getLogger("station.tui")


def describe(exc: BaseException, doing: str = "") -> str:
    """A sentence naming what failed and what to do; never a traceback.

    Driver errors carry their own hint (what to check); input errors name the file/field.
    Anything else is unexpected: logged with its traceback, summarised on screen.
    """
    prefix = f"{doing}: " if doing else ""
    if isinstance(exc, DriverError):
        return f"{prefix}{exc}"
    if isinstance(exc, ValueError):  # InputError, PlanError, SchemaError and friends
        return f"{prefix}{exc}"
    if isinstance(exc, FileNotFoundError):
        return f"{prefix}file not found: {exc.filename or exc}. Check the path."
    if isinstance(exc, PermissionError):
        return f"{prefix}permission denied: {exc.filename or exc}. Choose a writable folder."
    if isinstance(exc, OSError):
        return f"{prefix}{exc.strerror or exc}{f' ({exc.filename})' if exc.filename else ''}. Check the device or path."
    log.error("unexpected error %s", doing or "", exc_info=exc)
    return (f"{prefix}unexpected {type(exc).__name__}: {exc}. The drives were left stopped; "
            "details are in the log (station-ui.log). Please report it.")
