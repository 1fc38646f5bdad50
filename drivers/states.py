"""Named states the drivers report, as enums (their values are the strings in files and logs).

`StrEnum` members compare equal to their string values, so a recording or audit log written
before these enums existed reads the same, and what is written stays as it was.
"""

from __future__ import annotations

from enum import StrEnum


class DriveState(StrEnum):
    """CiA 402 power state of a drive, as `DriveStatus.state` reports it."""

    NOT_READY = "not_ready"
    SWITCH_ON_DISABLED = "switch_on_disabled"
    READY_TO_SWITCH_ON = "ready_to_switch_on"
    SWITCHED_ON = "switched_on"
    OPERATION_ENABLED = "operation_enabled"
    QUICK_STOP_ACTIVE = "quick_stop_active"
    FAULT = "fault"


class FaultKind(StrEnum):
    """What went wrong at one point of a sweep (the `kind` of a Fault event and a recorded fault)."""

    BEAM_BREAK = "beam_break"   # the interferometer lost its beam
    DRIVE_FAULT = "drive_fault"  # the drive latched a fault
    TIMEOUT = "timeout"          # a device did not answer, or the axis did not arrive in time
    FRAMING = "framing"          # an answer arrived garbled
    ERROR = "error"              # anything else (recorded by older versions and imports)
