"""The fleet's decision of a leg is the one its certificate and `station report` state: real
session files (a calibration and a later verification) indexed in a catalog, decided by the web
view's query and by the ISO 230-2 report of the files themselves, against the same tolerances."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.sim.plant import default_leg_configs
from station.catalog.readers import session_rec
from station.catalog.store import Catalog
from station.services.report_jobs import session_decisions
from station.services.synth import synth_session
from station.web.queries import latest_decisions
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
