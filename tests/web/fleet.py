"""A small known fleet written through the catalog's own API (readers.Rec -> store), and what the
web view must show of it. Values um; times UTC.

L300: HX-0001 (3 calibrations at ST-A, then one at ST-B reading E and B 3 um higher with U 0.5:
      |E_n| > 1), a table, its push to drive D1 and a verification; HX-0002 (2 at ST-B and one
      aborted session, which is no calibration); HX-0003 (one at ST-A in 2023: due long ago, U so
      large that no decision can be made).
L450: HX-0004 (ST-A and ST-B agreeing within U: |E_n| <= 1); HX-0005 (a table only: never calibrated).
"""

from __future__ import annotations

import hashlib

from station.catalog.readers import Rec

TABLE_SHA = hashlib.sha256(b"HX-0001 table").hexdigest()
TOLERANCES_TOML = """
[tolerances.L300]
E_um = 12.0
B_um = 4.0
R_um = 6.0
"""
EXPECT = {
    "legs": 5, "L300": 3, "L450": 2, "cal_L300": 7, "cal_L450": 2,
    "calibrations": {"HX-0001": 4, "HX-0002": 2, "HX-0003": 1, "HX-0004": 2, "HX-0005": 0},
    "compared": {"HX-0001": True, "HX-0004": False},  # serial -> flagged
    "due_by_2025_06_01": {"HX-0003", "HX-0005"},
    # ISO 14253-1 of the latest completed session against [tolerances.L300] (L450 has none):
    # HX-0001 B 5.5 - 0.5 > 4; HX-0002 all within; HX-0003 7 +- 6 straddles 12 (B, R likewise)
    "decisions": {"HX-0001": "does not conform", "HX-0002": "conforms", "HX-0003": "cannot decide",
                  "HX-0004": "no tolerance stated", "HX-0005": "-"},
}
TYPES = {"HX-0001": "L300", "HX-0002": "L300", "HX-0003": "L300", "HX-0004": "L450", "HX-0005": "L450"}


def _key(*parts) -> str:
    return hashlib.sha256("|".join(map(str, parts)).encode()).hexdigest()


def _session(serial: str, time_utc: str, station: str, e: float, b: float, r: float, u: float = 0.5,
             outcome: str = "completed") -> Rec:
    key = _key("session", serial, time_utc, station)
    rec = Rec(kind="session", key=key, time_utc=time_utc, station_id=station, operator="test", outcome=outcome,
              path=f"/runs/{serial}/{time_utc[:10]}.h5", sha256=key)
    rec.legs[1] = {"leg_serial": serial, "E_um": e, "E_U_um": u, "B_um": b, "B_U_um": u, "R_um": r, "R_U_um": u,
                   "A_um": 1.0, "A_U_um": 0.2, "M_um": e + 1, "M_U_um": u}
    rec.leg_info[serial] = {"part_number": "P-7", "leg_type": TYPES[serial], "screw_lot": "L1"}
    return rec


def records() -> list[Rec]:
    recs = [
        _session("HX-0001", "2024-01-10T09:00:00Z", "ST-A", 8.0, 2.0, 3.0),
        _session("HX-0001", "2024-06-10T09:00:00Z", "ST-A", 8.6, 2.2, 3.3),
        _session("HX-0001", "2025-01-10T09:00:00Z", "ST-A", 9.1, 2.5, 3.5),
        _session("HX-0001", "2025-02-01T09:00:00Z", "ST-B", 12.1, 5.5, 3.6),
        _session("HX-0002", "2024-03-01T10:00:00Z", "ST-B", 6.0, 1.5, 2.0),
        _session("HX-0002", "2024-09-01T10:00:00Z", "ST-B", 6.5, 1.7, 2.1),
        _session("HX-0002", "2024-10-01T10:00:00Z", "ST-B", 99.0, 99.0, 99.0, outcome="aborted"),
        _session("HX-0003", "2023-03-01T08:00:00Z", "ST-A", 7.0, 1.9, 2.5, u=6.0),  # every interval straddles
        _session("HX-0004", "2025-03-01T08:00:00Z", "ST-A", 10.0, 3.0, 4.0),
        _session("HX-0004", "2025-03-05T08:00:00Z", "ST-B", 10.3, 3.2, 4.1),
    ]
    table = Rec(kind="table", key=TABLE_SHA, time_utc="2025-01-10T10:00:00Z", station_id="ST-A",
                path="/runs/tables/HX-0001.csv", sha256=TABLE_SHA)
    table.legs[1] = {"leg_serial": "HX-0001"}
    push = Rec(kind="push", key="push-1", time_utc="2025-01-10T10:05:00Z", station_id="ST-A", outcome="pushed")
    push.legs[1] = {"leg_serial": "HX-0001", "drive": "D1 (127.0.0.1:5020 unit 1)", "table_sha256": TABLE_SHA}
    verify = Rec(kind="verification", key="verify-1", time_utc="2025-01-10T11:00:00Z", station_id="ST-A",
                 outcome="completed")
    verify.legs[1] = {"leg_serial": "HX-0001", "verification_ratio": 1.2}
    only_table = Rec(kind="table", key=_key("t5"), time_utc="2025-04-01T10:00:00Z", station_id="ST-A",
                     path="/runs/tables/HX-0005.csv", sha256=_key("t5"))
    only_table.legs[1] = {"leg_serial": "HX-0005"}
    only_table.leg_info["HX-0005"] = {"leg_type": "L450"}
    return recs + [table, push, verify, only_table]


def write_certificate(runs_dir, serial: str = "HX-0001", number: str = "C-2025-0001") -> bytes:
    """A certificate as `station certificate` leaves it (station.services.certificate_jobs): the PDF
    (2 pages, fpdf2) and the report's index naming it; the PDF's bytes."""
    import json

    from fpdf import FPDF

    folder = runs_dir / "certificates"
    folder.mkdir(parents=True, exist_ok=True)
    pdf = FPDF()
    for page in (1, 2):
        pdf.add_page()
        pdf.set_font("Helvetica", size=12)
        pdf.cell(0, 10, f"Certificate {number} for {serial}, page {page} of 2")
    data = bytes(pdf.output())
    (folder / f"{number}_r1.pdf").write_bytes(data)
    (folder / f"{number}.index.json").write_text(json.dumps({"report_no": number, "revisions": [
        {"revision": 1, "status": "issued", "issued_utc": "2025-01-11T09:00:00Z", "pdf": f"{number}_r1.pdf",
         "json": f"{number}_r1.json", "serial": serial}]}))
    return data
