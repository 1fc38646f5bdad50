"""The fleet's decision of a leg is the one its certificate and `station report` state: real
session files (a calibration and a later verification) indexed in a catalog, decided by the web
view's query and by the ISO 230-2 report of the files themselves, against the same tolerances."""

from __future__ import annotations

import re

import numpy as np
import pytest

from drivers.plant.leg import default_leg_configs
from station.catalog.readers import session_rec
from station.catalog.store import Catalog
from station.services.report_jobs import session_decisions
from procedures.synthetic import synth_session
from station.catalog.queries import latest_decisions
from tests.tooling import write_identified_session

# as found: loose enough to conform; as left: E within 0.001 um, which no measurement proves
TOML = "[tolerances.HX300]\nE_um = 40.0\nB_um = 10.0\n[tolerances.HX300.as_left]\nE_um = 0.001\n"


@pytest.mark.parametrize("with_verification", [False, True])
def test_web_decision_is_the_reports(tmp_path, with_verification):
    from procedures.io.recording.reader import read_session
    from station.web.extensions import decision_tolerances_of

    (tmp_path / "station.toml").write_text(TOML)
    tolerances = decision_tolerances_of(tmp_path / "station.toml")
    targets = np.linspace(-90.0, 90.0, 11)
    cal = write_identified_session(tmp_path / "cal.h5", synth_session({1: default_leg_configs(0)[0]}, targets, seed=1),
                                   plan={"kind": "iso230"}, started_utc="2026-03-01T08:00:00.000000Z")
    files = [cal]
    if with_verification:
        files.append(write_identified_session(tmp_path / "ver.h5",
                                              synth_session({1: default_leg_configs(0)[0]}, targets, seed=2),
                                              plan={"kind": "verification"}, started_utc="2026-03-02T08:00:00.000000Z"))
    catalog = Catalog(local=tmp_path / "catalog.sqlite", station_id="bench-1")
    catalog.ingest([session_rec(f) for f in files])
    shown = latest_decisions(catalog.engine, {"HX-0042": "HX300"}, tolerances)
    catalog.close()
    tol_json = {k: t.to_json() for k, t in tolerances.items()}
    (stated,) = session_decisions(read_session(files[-1]), tolerances=tol_json)["decisions"]["legs"].values()
    assert shown == {"HX-0042": stated["overall"]}
    # the stage follows the session: as found conforms, as left (E 0.001 um) cannot be met
    assert stated["overall"] == ("does not conform" if with_verification else "conforms")


def test_verdicts_stored_at_ingest_filter_the_fleet(tmp_path):
    """Revision 0004: a session's verdict is decided once at ingest (readers.decide_legs) and the
    fleet's decision filter reads it; a row stored undecided is decided at request time against
    the web's tolerances. Three legs: conforming and not conforming decided at ingest (E 2 and
    E 9 against 6 um), one stored undecided (its type unknown at ingest) that conforms."""
    from fastapi.testclient import TestClient

    from procedures.reporting.decision import Tolerance
    from station.catalog.readers import Rec, decide_legs
    from station.web.app import WebSettings, create_app
    from station.web.engine import open_readonly
    from station.catalog import db

    tol = {"HX300": Tolerance("HX300", {"E": 6.0}, {"E": 3.0})}
    recs = []
    for i, (serial, e) in enumerate((("HX-0001", 2.0), ("HX-0002", 9.0), ("HX-0003", 2.5))):
        rec = Rec(kind="session", key=f"k{i}", time_utc=f"2026-01-0{i + 1}T00:00:00Z", station_id="ST-A",
                  outcome="completed", path=f"/r/{i}.h5", sha256=f"k{i}")
        rec.legs[1] = {"leg_serial": serial, "E_um": e, "E_U_um": 0.2}
        rec.leg_info[serial] = {"leg_type": "HX300", "part_number": None, "screw_lot": None}
        recs.append(decide_legs(rec, tol if serial != "HX-0003" else {}))
    assert [r.legs[1].get("decision") for r in recs] == ["conforms", "does not conform", None]
    cat = Catalog(local=tmp_path / "c.sqlite", station_id="ST-A")
    cat.ingest(recs)
    cat.close()
    engine = open_readonly(db.sqlite_url(tmp_path / "c.sqlite"))
    with TestClient(create_app(engine, WebSettings(decision_tolerances=tol))) as client:
        listed = {v: set(re.findall(r'<a href="/leg/([^"]+)"', client.get("/", params={"decision": v}).text))
                  for v in ("conforming", "not-conforming")}
    engine.dispose()
    assert listed == {"conforming": {"HX-0001", "HX-0003"}, "not-conforming": {"HX-0002"}}
