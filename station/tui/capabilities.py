"""Pieces of the station the UI uses when they are installed, in one place.

Some procedures (push/verify/rollback, replay devices) arrive later than the UI. The screens ask
here and, when a piece is missing, say "not available yet" instead of faking a result.
"""

from __future__ import annotations

import importlib
from typing import Any

NOT_AVAILABLE = "{what} is not available yet in this build ({where} is missing)."

# what -> candidate (module, attribute) pairs, first found wins
PIECES: dict[str, list[tuple[str, str]]] = {
    "replay": [("station.services.wiring", "open_replay_rig")],
    "iso230": [("procedures.reporting.iso230", "evaluate")],
}


def find(what: str) -> Any | None:
    """The callable for `what`, or None when it is not installed."""
    for module, attr in PIECES.get(what, []):
        try:
            mod = importlib.import_module(module)
        except ImportError:
            continue
        fn = getattr(mod, attr, None)
        if fn is not None:
            return fn
    return None


def missing_text(what: str, label: str) -> str:
    where = " / ".join(f"{m}.{a}" for m, a in PIECES.get(what, []))
    return NOT_AVAILABLE.format(what=label, where=where)
