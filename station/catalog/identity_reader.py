"""A tolerant reader of the identity a file carries (schema 1.1 sessions' /meta `identity`, a
model's `identity` key, an audit entry's `leg_serial`/`station_id`, a table CSV's
`# leg_serial: X` lines). Anything missing or malformed reads as None: a 1.0 file is indexed
with unknown serials, never refused. (To be unified with the identity reader of the sessions.)
"""

from __future__ import annotations

import json
from typing import Any


def text(value: Any) -> str | None:
    """A non-empty string, else None (numbers are written as text; anything else is None)."""
    if isinstance(value, bool) or value is None:
        return None
    if isinstance(value, (int, float)):
        try:
            value = str(value)
        except ValueError:  # an integer of more digits than Python converts
            return None
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    if not isinstance(value, str):
        return None
    value = value.strip()
    return value[:128] if value else None


def _dict(value: Any) -> dict:
    return value if isinstance(value, dict) else {}


def parse_identity(raw: Any) -> dict:
    """The identity dict from JSON text or an already parsed object ({} when absent/invalid)."""
    if isinstance(raw, bytes):
        raw = raw.decode("utf-8", "replace")
    if isinstance(raw, str):
        try:
            raw = json.loads(raw)
        except (ValueError, RecursionError):
            return {}
    return raw if isinstance(raw, dict) else {}


def station_of(identity: dict) -> tuple[str | None, str | None]:
    s = _dict(identity.get("station"))
    return text(s.get("id")), text(s.get("host"))


def instrument_of(identity: dict) -> dict | None:
    i = _dict(identity.get("instrument"))
    serial = text(i.get("serial"))
    if serial is None:
        return None
    return {"serial": serial, "model": text(i.get("model")), "calibration_due": text(i.get("calibration_due")),
            "calibrated_on": text(i.get("calibrated_on"))}


def legs_of(identity: dict) -> dict[int, dict]:
    """{leg number: {"serial", "part_number", "leg_type", "screw_lot", "drive"}} of the legs that
    carry a serial."""
    out: dict[int, dict] = {}
    for key, value in _dict(identity.get("legs")).items():
        try:
            leg = int(key)
        except (TypeError, ValueError):
            continue
        v = _dict(value)
        serial = text(v.get("serial"))
        if serial is None or not 1 <= leg <= 99:
            continue
        drive = _dict(v.get("drive"))
        drive_text = " ".join(t for t in (text(drive.get("vendor")), text(drive.get("product_code")),
                                          text(drive.get("serial"))) if t) or None
        out[leg] = {"serial": serial, "part_number": text(v.get("part_number")), "leg_type": text(v.get("leg_type")),
                    "screw_lot": text(v.get("screw_lot")), "drive": drive_text}
    return out


def table_serials(lines: list[str]) -> tuple[dict[int, str], str | None]:
    """Serials named by `# leg_serial: X` (all legs) or `# leg_serial: 3=X` (leg 3) comment lines."""
    per_leg: dict[int, str] = {}
    common: str | None = None
    for line in lines:
        s = line.strip()
        if not s.startswith("#"):
            continue
        key, _, value = s[1:].partition(":")
        if key.strip() != "leg_serial":
            continue
        leg, eq, serial = value.partition("=")
        if eq and leg.strip().isdecimal() and len(leg.strip()) <= 2:
            if text(serial):
                per_leg[int(leg.strip())] = text(serial)
        elif text(value):
            common = text(value)
    return per_leg, common
