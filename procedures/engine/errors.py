"""Errors for bad input to procedures: each names what was wrong, where, and what to do."""

from __future__ import annotations


class InputError(ValueError):
    """Bad input (file, row, field). The message is shown to the user as is, without traceback."""


class SchemaError(InputError):
    """A recording or model file does not follow a schema this version understands."""


class PlanError(InputError):
    """A sweep plan is invalid, e.g. targets outside the drive's soft limits."""
