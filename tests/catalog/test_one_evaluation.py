"""One evaluation of a session (issue 33.3): the catalog's record of a session file holds what
`station report` writes into iso230-2.json for it (every ISO 230-2 value with U, each target's
mean deviation with U, the leg's verdict against the tolerances the session recorded), and the
identity the sessions' reader parsed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from drivers.plant.leg import default_leg_configs
from station.catalog.models import FIGURES
from station.catalog.readers import session_identity, session_rec
from station.cli import main
from procedures.synthetic import synth_session
from tests.tooling import write_identified_session

# E of the synthetic leg is about 3 um: an as-found limit of 1 um does not conform (a real verdict);
# recorded as a session records its config's [tolerances] (Tolerance.to_json)
TOLERANCES = {"HX300": {"leg_type": "HX300", "as_found_um": {"E": 1.0, "B": 50.0}, "as_left_um": {"E": 1.0},
                        "source": "test"}}


@pytest.fixture(scope="module")
def session_and_report(tmp_path_factory):
    d = tmp_path_factory.mktemp("one")
    points = synth_session({1: default_leg_configs(0)[0]}, np.linspace(-90.0, 90.0, 9), cycles=3, seed=4)
    path = write_identified_session(d / "cal.h5", points, station_config={"tolerances": TOLERANCES},
                                    plan={"kind": "iso230"})
    assert main(["report", str(path), "--out", str(d / "rep")]) == 0
    return path, json.loads((d / "rep" / "iso230-2.json").read_text())


def test_the_record_holds_the_reports_values_targets_and_verdict(session_and_report):
    path, report = session_and_report
    rec = session_rec(path)
    row, leg = rec.legs[1], report["legs"]["1"]
    for name in FIGURES:
        assert row[f"{name}_um"] == pytest.approx(leg["values"][name]["value_um"], abs=1e-9)
        assert row[f"{name}_U_um"] == pytest.approx(leg["values"][name]["U_um"], abs=1e-9)
    targets = rec.summary["targets"]["1"]
    assert len(targets) == len(leg["targets"]) == 18
    for (direction, target_mm, mean_um, u_um), t in zip(targets, leg["targets"]):
        assert (direction, target_mm) == (t["direction"], t["target_mm"])
        assert (mean_um, u_um) == pytest.approx((t["mean_um"], t["U_um"]), abs=1e-9)
    verdict = report["decisions"]["legs"]["1"]["overall"]
    assert row["decision"] == verdict == "does not conform"


def test_the_identity_is_the_readers(session_and_report):
    path, report = session_and_report
    identity = session_identity(path)
    assert identity["legs"]["1"]["serial"] == report["identification"]["leg_identity"]["1"]["serial"] == "HX-0042"
    assert identity["station"]["id"] == report["identification"]["station"]["id"] == "bench-1"
