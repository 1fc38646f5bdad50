"""The identity a session records (procedures/io/recording/identity.py), put together from the
config, the serials entered for this session and what each drive says about itself."""

from __future__ import annotations

import datetime as _dt
from types import MappingProxyType
from typing import Iterable, Mapping

from drivers.errors import DriverError
from drivers.interfaces import ServoAxis
from procedures.compensation.audit import AuditLog
from procedures.vocabulary import InputError
from procedures.io.recording.identity import (
    DriveIdentity,
    LegIdentity,
    SessionIdentity,
    StationIdentity,
    calibration_warnings,
    instrument_identity,
)
from station.services.config import StationConfig, _hostname
from station.services.serials import merged_leg_identity, read_serials_file


def leg_fields(cfg: StationConfig, entered: Mapping[int, Mapping[str, str]] | None = None,
               serials_file: str | None = None) -> dict[int, dict[str, str]]:
    """Every leg's identity fields: [legs.N], then the serials file (`serials_file`, else
    [station] serials_file), then `entered` (--serial, the Sweep page)."""
    path = serials_file or cfg.serials_file
    from_file = read_serials_file(path) if path else {}
    merged = merged_leg_identity(cfg.leg_identity, from_file, entered or {})
    _one_leg_per_serial(merged, [(cfg.leg_identity, f"[legs.N] of {cfg.source}"), (from_file, f"the serials file {path}"),
                                 (entered or {}, "--serial")])
    return merged


def _one_leg_per_serial(merged: Mapping[int, Mapping[str, str]], sources) -> None:
    """A serial names one leg: two legs given one serial (a copied row, a typo) are refused naming
    both legs and where each got it, before anything is recorded."""
    first: dict[str, int] = {}
    for leg in sorted(merged):
        serial = merged[leg].get("serial")
        if not serial:
            continue
        if serial in first:
            other = first[serial]
            whence = {src for ident, src in sources for lg in (other, leg)
                      if (ident.get(lg) or {}).get("serial") == serial}
            raise InputError(f"serial {serial} is given to both leg {other} and leg {leg} (by {' and '.join(sorted(whence))}); "
                             "a serial names one leg: correct it and run again; nothing was recorded")
        first[serial] = leg


def configured_serials(cfg: StationConfig) -> dict[int, str]:
    """leg -> the serial the leg carries, as configured ([legs.N] serial, [station] serials_file):
    what a push checks a table's serial against."""
    return {leg: f["serial"] for leg, f in leg_fields(cfg).items() if f.get("serial")}


def station_audit_log(cfg: StationConfig, path: str | None = None) -> AuditLog:
    """The audit log of this station (`path`, default <recordings_dir>/audit.jsonl): entries carry
    its operator, station id and each leg's configured serial."""
    return AuditLog(path or cfg.audit_path, operator=cfg.operator, station_id=cfg.station_id,
                    leg_serials=configured_serials(cfg))


def drive_identity(axis: ServoAxis, cfg_fields: Mapping[str, str]) -> DriveIdentity:
    """What the drive says (Modbus 43/14 and its serial register, drivers/modbus/client.py), with
    `[legs.N] drive_serial` for a drive that cannot tell its serial. A drive that does not answer
    is named from the config (source "config")."""
    ask = getattr(axis, "drive_identity", None)
    got: dict = {}
    if ask is not None:
        try:
            got = dict(ask())
        except DriverError:
            got = {}
    serial = got.get("serial") or cfg_fields.get("drive_serial") or None
    return DriveIdentity(got.get("vendor"), got.get("product_code"), got.get("revision"), serial,
                         got.get("source") or "config")


def instrument_of(cfg: StationConfig, on: _dt.date | None = None):
    m = cfg.metrology
    return instrument_identity(m.model, m.serial, m.calibration_due, m.calibration_date, on)


def session_identity(cfg: StationConfig, legs: Iterable[int], axes: Mapping[int, ServoAxis], software_version: str,
                     entered: Mapping[int, Mapping[str, str]] | None = None, serials_file: str | None = None,
                     on: _dt.date | None = None) -> SessionIdentity:
    """The identity of a session on `legs` (drives in `axes`), with the laser's calibration
    warnings for the day `on` (default today)."""
    fields = leg_fields(cfg, entered, serials_file)
    leg_ids = {}
    for leg in legs:
        f = fields.get(int(leg), {})
        leg_ids[int(leg)] = LegIdentity(f.get("serial"), f.get("part_number"), f.get("leg_type"), f.get("screw_lot"),
                                        drive_identity(axes.get(leg), f))
    instrument = instrument_of(cfg, on)
    return SessionIdentity(
        station=StationIdentity(cfg.station_id, _hostname()), operator=cfg.operator,
        software_version=software_version, instrument=instrument, legs=MappingProxyType(leg_ids),
        warnings=tuple(calibration_warnings(instrument, on)),
    )
