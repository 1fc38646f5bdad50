"""Errors of the replay devices. Each names the recording and what to do."""

from __future__ import annotations

from drivers.errors import DriverError


class ReplayDataError(DriverError, ValueError):
    """The recording cannot be replayed (a value the devices must report is unknown, a fault
    kind the devices cannot reproduce, a duplicate point). Raised when the replay is opened."""

    hint = "Replay sessions recorded on a rig (sim, live or replay); analyse imported data directly."


class ReplayMismatch(DriverError):
    """A procedure asked the replay devices for something the recording does not hold (a leg,
    a target, or points in another order than recorded). The message names the first mismatch."""

    hint = "A replay answers only the plan it recorded, in the recorded order (`station replay` runs it)."
