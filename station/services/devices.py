"""What a front end may know of the devices: the interface's value types and the driver errors.

Front ends (station/tui, station/commands) import these from here, never from drivers.*
(tests/test_layering.py), so a new drive family changes drivers/ and services/wiring.py only."""

from __future__ import annotations

from drivers.errors import DriveFault, DriverError, SoftLimitError
from drivers.interfaces import DriveLimits, DriveStatus, Environment, Reading

__all__ = ["DriveFault", "DriverError", "SoftLimitError", "DriveLimits", "DriveStatus", "Environment", "Reading"]
