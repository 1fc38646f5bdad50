"""Errors raised by drivers. Each carries a sentence a technician can act on."""

from __future__ import annotations


class DriverError(Exception):
    """Base class: something went wrong talking to, or inside, a device."""

    hint: str = ""

    def __init__(self, message: str, hint: str = ""):
        super().__init__(message)
        if hint:
            self.hint = hint

    def __str__(self) -> str:
        text = super().__str__()
        return f"{text} {self.hint}".strip() if self.hint else text


class CommTimeout(DriverError):
    """The device did not answer within the configured timeout."""

    hint = "Check the cable/port/address and that the device is powered; see `station sim` for the simulated rig."


class FramingError(DriverError):
    """A reply arrived but was malformed (bad terminator, checksum or field)."""

    hint = "Check the serial settings (baud rate, parity) and the cable shielding."


class BeamBreak(DriverError):
    """The interferometer beam is interrupted or its signal is too weak."""

    hint = "Clear the beam path and re-align the optics, then retry."


class CountLost(BeamBreak):
    """The interferometer lost its fringe count (a velocity overflow): every position is invalid
    until its origin is set again (the sweep re-references the leg: procedures/acquisition/sweep.py)."""

    hint = "The leg is taken back to its reference and the laser zeroed there before the point is measured again."


class DriveFault(DriverError):
    """The drive reports a fault. `code` is the drive's fault code."""

    hint = "Clear the cause, then reset the fault (`station` Rig screen, or the drive panel)."

    def __init__(self, message: str, code: int = 0, hint: str = ""):
        super().__init__(message, hint)
        self.code = code


class SoftLimitError(DriverError):
    """A requested target lies outside the drive's soft travel limits. Nothing moved."""

    hint = "Choose targets within the soft limits of the drive profile."


class TableError(DriverError):
    """A compensation table was refused, failed read-back, or failed its checksum."""

    hint = "The previously active table is still active."


class TableRefused(TableError, ValueError):
    """A table that does not fit what the device holds (`TableSpec.check`), refused before
    anything was written. The one exception for a refused table, wherever it is checked: making
    it, reading a CSV, pushing it, encoding it for a drive."""

    hint = "Nothing was written."
