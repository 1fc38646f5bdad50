"""Who and what an imported session measured (issue 33 part 5, docs/import.md "Identity"): the leg
serials, part number, type, screw lot, the station, the stage (calibration / verification /
other), the date of the measurement and the laser, given by `station import` options, the map's
[identity] section, or the station config (--config: [legs.N], [station] id, [metrology]); in
that order of precedence. With them an imported session is decided and certified like a
recorded one.

Everything given is checked before the file is read (`ImportIdentity.given`), and what depends on
the legs the file holds once it has been read (`identity_json`), before anything is written: a
refusal is one line naming the option or map key.
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from typing import Any, Mapping

from procedures.vocabulary import InputError
from procedures.io.recording.identity import (InstrumentIdentity, LegIdentity, SessionIdentity, StationIdentity,
                                              instrument_identity)

STAGES = ("calibration", "verification", "other")
LEG_KEYS = ("serial", "part_number", "leg_type", "screw_lot")
LASER_KEYS = ("laser_model", "laser_serial", "laser_calibrated_on", "laser_calibration_due")


@dataclass
class ImportIdentity:
    """What was given, checked; `where[key]` names where each value came from for the messages."""

    serials: dict[int, str] = field(default_factory=dict)  # leg -> serial (LEG=SERIAL)
    serial: str | None = None  # the serial of a file holding one leg
    leg: dict[str, str] = field(default_factory=dict)  # part_number, leg_type, screw_lot for every leg
    config_legs: dict[int, dict[str, str]] = field(default_factory=dict)  # [legs.N] of --config
    station: str | None = None
    stage: str | None = None
    started_utc: str | None = None
    laser: dict[str, str] = field(default_factory=dict)  # model, serial, calibrated_on, calibration_due
    where: dict[str, str] = field(default_factory=dict)

    @property
    def any(self) -> bool:
        return bool(self.serials or self.serial or self.leg or self.config_legs or self.station or self.stage
                    or self.started_utc or self.laser)

    def identity_json(self, legs: list[int], operator: str, software_version: str) -> dict[str, Any]:
        """The session's /meta/identity for the legs the file holds; InputError for a LEG=SERIAL
        of a leg the file does not hold, or a plain serial given to a file of several legs."""
        from station.services.serials import check_serial  # noqa: PLC0415

        for leg in self.serials:
            if leg not in legs:
                raise InputError(f"{self.where.get('serials', '--serial')} {leg}=...: the file holds legs {legs}, "
                                 f"not leg {leg}")
        if self.serial and len(legs) != 1:
            raise InputError(f"{self.where.get('serial', '--serial')} {self.serial}: the file holds legs {legs}; "
                             "say which leg carries it: --serial LEG=SERIAL")
        out = {}
        for leg in legs:
            cfg = self.config_legs.get(leg, {})
            serial = self.serials.get(leg) or (self.serial if len(legs) == 1 else None) or cfg.get("serial") or None
            if serial:
                check_serial(serial, self.where.get("serial", "--serial"))
            out[leg] = LegIdentity(serial=serial, **{k: self.leg.get(k) or cfg.get(k) or None for k in LEG_KEYS[1:]})
        day = _dt.date.fromisoformat(self.started_utc[:10]) if self.started_utc else None
        ins = (instrument_identity(self.laser.get("model"), self.laser.get("serial"),
                                   self.laser.get("calibration_due"), self.laser.get("calibrated_on"), day)
               if self.laser else InstrumentIdentity())
        ident = SessionIdentity(station=StationIdentity(id=self.station or None, host=None), operator=operator or None,
                                software_version=software_version, legs=out, instrument=ins)
        return ident.to_json()


def _date(value: Any, where: str) -> str:
    text = value.isoformat() if isinstance(value, _dt.date) else value
    if not isinstance(text, str):
        raise InputError(f"{where} {value!r}: give a date as YYYY-MM-DD")
    try:
        return _dt.date.fromisoformat(text.strip()).isoformat()
    except ValueError:
        raise InputError(f"{where} {value!r}: give a date as YYYY-MM-DD") from None


def _when(value: Any, where: str) -> str:
    """A date or date and time as the session's start (UTC, the writer's format); a time without
    a zone is taken as UTC."""
    if isinstance(value, _dt.datetime):
        t = value
    elif isinstance(value, _dt.date):
        t = _dt.datetime(value.year, value.month, value.day)
    elif isinstance(value, str):
        try:
            t = _dt.datetime.fromisoformat(value.strip().replace("Z", "+00:00"))
        except ValueError:
            raise InputError(f"{where} {value!r}: give the date of the measurement as YYYY-MM-DD or "
                             "YYYY-MM-DDTHH:MM[:SS] (UTC)") from None
    else:
        raise InputError(f"{where} {value!r}: give the date of the measurement as YYYY-MM-DD")
    if t.tzinfo is not None:
        t = t.astimezone(_dt.timezone.utc).replace(tzinfo=None)
    if t > _dt.datetime.now(_dt.timezone.utc).replace(tzinfo=None) + _dt.timedelta(days=1):
        raise InputError(f"{where} {value!r}: a measurement in the future")
    return t.strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def given(options: Mapping[str, Any], map_identity: Mapping[str, Any] | None, map_path: str = "",
          config=None) -> ImportIdentity:
    """The identity from the command line `options` (serial: list of SERIAL or LEG=SERIAL,
    part_number, leg_type, screw_lot, station, stage, measured), the map's [identity] and the
    station `config` (StationConfig or None), each value checked; options win over the map, the
    map over the config."""
    from station.services.serials import check_serial  # noqa: PLC0415

    ii = ImportIdentity()
    m = dict(map_identity or {})

    def mkey(key: str) -> str:
        return f"{map_path}, key identity.{key}:"

    for key, value in m.items():
        if key in ("measured_utc", "laser_calibrated_on", "laser_calibration_due"):
            continue  # dates: TOML may give a date literal, checked below
        if not isinstance(value, str) or not value.strip():
            raise InputError(f"{mkey(key)} {value!r} must be a non-empty string")
    # serials
    for text in options.get("serial") or []:
        leg, sep, serial = text.partition("=")
        if sep:
            try:
                n = int(leg)
            except ValueError:
                raise InputError(f"--serial {text!r}: give SERIAL, or LEG=SERIAL with LEG a leg number") from None
            check_serial(serial, f"--serial {n}=")
            ii.serials[n] = serial
        else:
            check_serial(text, "--serial")
            if ii.serial and ii.serial != text:
                raise InputError(f"--serial {ii.serial} and --serial {text}: one serial without a leg; give "
                                 "LEG=SERIAL for each leg")
            ii.serial = text
            ii.where["serial"] = "--serial"
    if not ii.serial and not ii.serials and m.get("serial"):
        check_serial(m["serial"].strip(), f"{map_path}, key identity.serial")
        ii.serial = m["serial"].strip()
        ii.where["serial"] = f"{map_path}, key identity.serial"
    for key in LEG_KEYS[1:]:
        v = options.get(key) or (m.get(key) or "").strip() or None
        if v:
            ii.leg[key] = v
    ii.station = options.get("station") or (m.get("station") or "").strip() or (
        config.id if config is not None and config.id else None)
    stage = options.get("stage") or (m.get("stage") or "").strip() or None
    if stage is not None and stage not in STAGES:
        where = "--stage" if options.get("stage") else mkey("stage")
        raise InputError(f"{where} {stage!r}: one of {', '.join(STAGES)}")
    ii.stage = stage
    if options.get("measured"):
        ii.started_utc = _when(options["measured"], "--measured")
    elif m.get("measured_utc") is not None:
        ii.started_utc = _when(m["measured_utc"], mkey("measured_utc"))
    for key in LASER_KEYS:
        v = m.get(key)
        if v is None:
            continue
        name = key.removeprefix("laser_")
        ii.laser[name] = _date(v, mkey(key)) if key in ("laser_calibrated_on", "laser_calibration_due") else v.strip()
    if config is not None:
        ii.config_legs = {int(n): dict(v) for n, v in (config.leg_identity or {}).items()}
        if not ii.laser:
            mc = config.metrology
            laser = {"model": mc.model, "serial": mc.serial, "calibrated_on": mc.calibration_date,
                     "calibration_due": mc.calibration_due}
            ii.laser = {k: v for k, v in laser.items() if v}
    return ii
