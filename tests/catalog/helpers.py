"""Sessions with identity for the catalog tests: written through the real SessionWriter, with the
schema 1.1 /meta `identity` attribute stamped on where the identity code does not write it."""

from __future__ import annotations

import json
from pathlib import Path

import h5py

from tests.tooling import default_legs_points


def identity(serials: dict[int, str], station: str = "ST-A", leg_type: str = "HX-L300",
             instrument_serial: str = "LZ-1", calibration_due: str = "2027-06-30") -> dict:
    return {"station": {"id": station, "host": f"{station.lower()}-pc"}, "operator": "jdoe", "software_version": "test",
            "instrument": {"model": "XL-80", "serial": instrument_serial, "calibration_due": calibration_due,
                           "calibrated_on": "2026-06-30", "traceable": True},
            "legs": {str(leg): {"serial": s, "part_number": "P-300", "leg_type": leg_type, "screw_lot": "L7",
                                "drive": {"vendor": "Sim", "product_code": "SD", "revision": "1", "serial": f"D{leg}",
                                          "source": "config"}} for leg, s in serials.items()}}


def stamp_identity(path: str | Path, ident: dict) -> None:
    """Set /meta identity on a session file (what the identity code writes in schema 1.1)."""
    with h5py.File(path, "a") as f:
        f["meta"].attrs["identity"] = json.dumps(ident)


def write_session(path: str | Path, serials: dict[int, str] | None = None, *, station: str = "ST-A",
                  started_utc: str = "2026-01-10T08:00:00.000000Z", seed: int = 0, cycles: int = 2,
                  step_mm: float = 15.0, leg_type: str = "HX-L300") -> Path:
    """A completed session of the legs in `serials` (default leg 1 without identity: a 1.0 file)."""
    from procedures.io.recording.writer import SessionWriter

    path = Path(path)
    legs = sorted(serials) if serials else [1]
    points = default_legs_points(legs, cycles, step_mm, seed)
    with SessionWriter.create(path, session_id=path.stem, operator="test", rig="sim", plan={"kind": "test"},
                              station_config={}, devices={}, software_version="test", started_utc=started_utc) as w:
        w.append_points(points)
        w.finish("completed")
    if serials:
        stamp_identity(path, identity(serials, station, leg_type))
    return path
