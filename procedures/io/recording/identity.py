"""Who and what a session measured: leg, drive, station, instrument, operator, software version.

Stored in a session file (schema 1.1) as the `/meta` attribute `identity`, JSON text:

    {"station": {"id": str, "host": str}, "operator": str, "software_version": str,
     "instrument": {"model": str|null, "serial": str|null, "calibration_due": "YYYY-MM-DD"|null,
                    "calibrated_on": "YYYY-MM-DD"|null, "traceable": bool},
     "legs": {"1": {"serial": str|null, "part_number": str|null, "leg_type": str|null,
                    "screw_lot": str|null,
                    "drive": {"vendor", "product_code", "revision", "serial": str|null,
                              "source": "modbus-device-id"|"config"|"sim"}}, ...},
     "warnings": [str, ...]}

`warnings` holds what was said at the sweep's start about the identity (a laser past its
calibration due date, no due date stated). A file without the attribute (schema 1.0, imports)
reads as `SessionIdentity.unknown()`: every field None, never an error (docs/session-schema.md).
"""

from __future__ import annotations

import datetime as _dt
import json
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping

from procedures.vocabulary import SchemaError

DRIVE_SOURCES = ("modbus-device-id", "config", "sim")
"""Where a drive's identity came from: read over Modbus (function 43/14), the station config (the
drive profile's [identity] and [legs.N]), or a simulated drive named without asking it."""

NOT_STATED = "calibration due date not stated: result not traceable"


@dataclass(frozen=True)
class StationIdentity:
    id: str | None = None
    host: str | None = None


@dataclass(frozen=True)
class InstrumentIdentity:
    """The laser: `calibration_due` / `calibrated_on` ISO dates (YYYY-MM-DD) or None (not stated);
    `traceable` True only when a due date was stated and not past on the day of the session."""

    model: str | None = None
    serial: str | None = None
    calibration_due: str | None = None
    calibrated_on: str | None = None
    traceable: bool = False


@dataclass(frozen=True)
class DriveIdentity:
    vendor: str | None = None
    product_code: str | None = None
    revision: str | None = None
    serial: str | None = None
    source: str | None = None  # one of DRIVE_SOURCES; None in a file without identity


@dataclass(frozen=True)
class LegIdentity:
    serial: str | None = None
    part_number: str | None = None
    leg_type: str | None = None
    screw_lot: str | None = None
    drive: DriveIdentity = field(default_factory=DriveIdentity)


@dataclass(frozen=True)
class SessionIdentity:
    """A session's identity as read (`read_identity`) or about to be written (`to_json`).
    `recorded` is False for a file that holds none (schema 1.0, an import)."""

    station: StationIdentity = field(default_factory=StationIdentity)
    operator: str | None = None
    software_version: str | None = None
    instrument: InstrumentIdentity = field(default_factory=InstrumentIdentity)
    legs: Mapping[int, LegIdentity] = field(default_factory=lambda: MappingProxyType({}))
    warnings: tuple[str, ...] = ()
    recorded: bool = True

    @classmethod
    def unknown(cls) -> "SessionIdentity":
        return cls(recorded=False)

    def leg(self, leg: int) -> LegIdentity:
        """Leg `leg`'s identity; every field None when the session does not say."""
        return self.legs.get(int(leg), LegIdentity())

    def leg_serial(self, leg: int) -> str | None:
        return self.leg(leg).serial

    def to_json(self) -> dict[str, Any]:
        """The `/meta/identity` object (module docstring)."""
        def leg_json(li: LegIdentity) -> dict:
            d = _fields(li, ("serial", "part_number", "leg_type", "screw_lot"))
            d["drive"] = _fields(li.drive, ("vendor", "product_code", "revision", "serial", "source"))
            return d
        return {
            "station": _fields(self.station, ("id", "host")),
            "operator": self.operator,
            "software_version": self.software_version,
            "instrument": _fields(self.instrument, ("model", "serial", "calibration_due", "calibrated_on",
                                                    "traceable")),
            "legs": {str(n): leg_json(li) for n, li in sorted(self.legs.items())},
            "warnings": list(self.warnings),
        }


def _fields(obj: Any, names: tuple[str, ...]) -> dict:
    return {n: getattr(obj, n) for n in names}


def model_identity(identity: SessionIdentity, legs) -> dict[str, Any]:
    """The `identity` key of a model file made from a session with `identity`, for `legs`:
    station, operator, software version and per leg serial, part number and type (None = not
    stated; a 1.0 session gives every field None)."""
    return {
        "station": _fields(identity.station, ("id", "host")),
        "operator": identity.operator,
        "software_version": identity.software_version,
        "legs": {str(leg): _fields(identity.leg(leg), ("serial", "part_number", "leg_type")) for leg in sorted(legs)},
    }


def model_leg_serials(model_identity_json: Any) -> dict[int, str]:
    """leg -> serial from a model's `identity` (legs without one left out); {} for a model without."""
    legs = (model_identity_json or {}).get("legs") if isinstance(model_identity_json, dict) else None
    if not isinstance(legs, dict):
        return {}
    return {int(k): v["serial"] for k, v in legs.items()
            if str(k).isdigit() and isinstance(v, dict) and isinstance(v.get("serial"), str) and v["serial"]}


# -- the laser's calibration state ---------------------------------------------------------------

def instrument_identity(model: str | None, serial: str | None, calibration_due: str | None,
                        calibrated_on: str | None, on: _dt.date | None = None) -> InstrumentIdentity:
    """The instrument with `traceable` decided for the day `on` (default today, UTC)."""
    due = calibration_due or None
    traceable = due is not None and _dt.date.fromisoformat(due) >= (on or _today())
    return InstrumentIdentity(model or None, serial or None, due, calibrated_on or None, traceable)


def calibration_warnings(instrument: InstrumentIdentity, on: _dt.date | None = None) -> list[str]:
    """What a session or report must say about the laser's calibration on the day `on`: past its
    due date, or no due date stated; [] when it is in calibration."""
    name = " ".join(v for v in (instrument.model, instrument.serial and f"s/n {instrument.serial}") if v) or "the laser"
    if not instrument.calibration_due:
        return [f"{name}: {NOT_STATED}"]
    due = _dt.date.fromisoformat(instrument.calibration_due)
    day = on or _today()
    if due < day:
        return [f"{name}: calibration was due {due.isoformat()}, {(day - due).days} day(s) before "
                f"{day.isoformat()}: result not traceable; have the laser calibrated"]
    return []


def _today() -> _dt.date:
    return _dt.datetime.now(_dt.timezone.utc).date()


# -- reading -------------------------------------------------------------------------------------

def identity_from_json(value: Any, where: str = "identity") -> SessionIdentity:
    """A SessionIdentity from the `/meta/identity` object; SchemaError naming the field for a
    value of the wrong type. Keys this version does not know are ignored (a newer minor)."""
    if not isinstance(value, dict):
        raise SchemaError(f"{where}: not a JSON object")

    def text(obj: dict, key: str, at: str) -> str | None:
        v = obj.get(key)
        if v is not None and not isinstance(v, str):
            raise SchemaError(f"{where}: {at}{key} must be text or null, got {v!r}")
        return v

    def section(obj: dict, key: str, at: str = "") -> dict:
        v = obj.get(key)
        v = {} if v is None else v
        if not isinstance(v, dict):
            raise SchemaError(f"{where}: {at}{key} must be an object, got {v!r}")
        return v

    st = section(value, "station")
    ins = section(value, "instrument")
    for key in ("calibration_due", "calibrated_on"):
        day = text(ins, key, "instrument.")
        if day is not None:
            try:
                _dt.date.fromisoformat(day)
            except ValueError:
                raise SchemaError(f"{where}: instrument.{key} = {day!r} is not a date YYYY-MM-DD") from None
    legs: dict[int, LegIdentity] = {}
    for key, leg in section(value, "legs").items():
        if not (isinstance(key, str) and key.isdigit() and isinstance(leg, dict)):
            raise SchemaError(f"{where}: legs.{key} must be a leg number with an object")
        at = f"legs.{key}."
        drive = section(leg, "drive", at)
        source = text(drive, "source", at + "drive.")
        legs[int(key)] = LegIdentity(
            *(text(leg, k, at) for k in ("serial", "part_number", "leg_type", "screw_lot")),
            drive=DriveIdentity(*(text(drive, k, at + "drive.") for k in ("vendor", "product_code", "revision",
                                                                            "serial")), source),
        )
    warnings = value.get("warnings")
    warnings = [] if warnings is None else warnings
    if not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings):
        raise SchemaError(f"{where}: warnings must be a list of text")
    return SessionIdentity(
        station=StationIdentity(text(st, "id", "station."), text(st, "host", "station.")),
        operator=text(value, "operator", ""),
        software_version=text(value, "software_version", ""),
        instrument=InstrumentIdentity(text(ins, "model", "instrument."), text(ins, "serial", "instrument."),
                                      ins.get("calibration_due"), ins.get("calibrated_on"),
                                      ins.get("traceable") is True),
        legs=MappingProxyType(legs),
        warnings=tuple(warnings),
    )


def identity_of_meta(meta_attrs: Mapping[str, Any], where: str) -> SessionIdentity:
    """The identity in a /meta attribute mapping (h5py attrs or a dict of text)."""
    if "identity" not in meta_attrs:
        return SessionIdentity.unknown()
    raw = meta_attrs["identity"]
    text = raw.decode("utf-8", "replace") if isinstance(raw, bytes) else str(raw)
    try:
        value = json.loads(text)
    except ValueError as exc:
        raise SchemaError(f"{where}: attribute /meta/identity is not valid JSON ({exc})") from None
    return identity_from_json(value, f"{where}: /meta/identity")
