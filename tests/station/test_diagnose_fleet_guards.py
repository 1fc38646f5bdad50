"""Issue 35, fleet twin guards: siblings that are the same measurement (by content) counted once
and named; a wind-up the target spacing cannot resolve not named; a scale against the fleet only
where the feature comparison supports it. Synthetic fleets from the plant, and the real ISO 230-2
sets of shared/data/real (several of which are one measurement under several names)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from drivers.plant.leg import default_leg_configs
from procedures.io.csv_io import import_csv
from procedures.io.recording.reader import read_session
from station.services.diagnosis_jobs import diagnose_session
from station.services.twins import load_twin
from tests.catalog.helpers import identity, stamp_identity
from tests.station.test_diagnose_fleet import TYPE, _index, _write

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "real"


def test_duplicate_siblings_are_counted_once_and_named(tmp_path):
    cfgs = default_leg_configs(3, 6)
    for i in range(4):
        _write(tmp_path / f"leg{i}.h5", cfgs[i], i, f"SN-{i}", 10 + i)
    for k in range(3):  # one session of SN-5's leg under three serials: the same readings, three files
        _write(tmp_path / f"copy{k}.h5", cfgs[5], 55, f"SN-C{k}", 20 + k)
    catalog, _ = _index(tmp_path)
    target = tmp_path / "leg0.h5"
    session = read_session(target)
    twin = load_twin(f"fleet:{TYPE}", session=session, path=target, catalog=lambda: catalog.engine)
    assert sorted(twin.fleet[1].serials) == ["SN-1", "SN-2", "SN-3", "SN-C0"]  # four independent siblings
    assert twin.info["duplicates"] == {"SN-C1": "SN-C0", "SN-C2": "SN-C0"}
    assert "duplicates counted once: SN-C1 (same as SN-C0), SN-C2 (same as SN-C0)" in twin.description
    report, _ = diagnose_session(session, target, twin)
    fl = report["legs"]["1"]["fleet"]
    assert fl["siblings"] == 4 and fl["duplicates_counted_once"] == {"SN-C1": "SN-C0", "SN-C2": "SN-C0"}
    assert fl["finding"] is None  # a clean leg among clean siblings


def _real_fleet(folder: Path, names: list[str]) -> dict[str, Path]:
    paths = {}
    for i, name in enumerate(names):
        out = folder / f"{name}.h5"
        import_csv(REAL / f"{name}.csv", out)
        stamp_identity(out, identity({1: name}, leg_type="ECMC-AX"))
        paths[name] = out
    return paths


@pytest.mark.skipif(not REAL.is_dir() and os.environ.get("CI") != "true",
                    reason="shared/data/real (the real ISO 230-2 sets) is not beside the checkout")
def test_real_sets_through_the_fleet_twin(tmp_path):
    names = ["ecmccomgui_report_2", "ecmccomgui_report_3", "ecmccomgui_report_5", "ecmccomgui_report_6",
             "ecmccomgui_report_7", "ecmccomgui_example_data_ISO230_2", "ecmccomgui_testdata_ISO230_2"]
    paths = _real_fleet(tmp_path, names)
    catalog, _ = _index(tmp_path)
    target = paths["ecmccomgui_report_7"]
    session = read_session(target)
    twin = load_twin("fleet:ECMC-AX", session=session, path=target, catalog=lambda: catalog.engine)
    # reports 3, 5 and 6 are one measurement; the example and test data .dat files hold the same readings
    assert twin.info["duplicates"] == {"ecmccomgui_report_5": "ecmccomgui_report_3",
                                       "ecmccomgui_report_6": "ecmccomgui_report_3",
                                       "ecmccomgui_testdata_ISO230_2": "ecmccomgui_example_data_ISO230_2"}
    assert twin.fleet[1].n == 3
    report, _ = diagnose_session(session, target, twin)
    leg = report["legs"]["1"]
    sigmas = [abs(r["sigma"]) for r in leg["fleet"]["features"] if r["sigma"] is not None]
    assert max(sigmas) < 100  # independent siblings: no "-352 sigma" from three copies of one spread
    for f in report["findings"]:
        assert f.get("variant") not in ("windup", "temperature+windup"), f  # 10 mm apart: not resolvable
        if f["effect"] == "scale":
            assert any(r["feature"] == "scale" and r["stands_out"] for r in leg["fleet"]["features"])
    scale = next(c for c in leg["candidates"] if c["effect"] == "scale")
    if not any(r["feature"] == "scale" and r["stands_out"] for r in leg["fleet"]["features"]):
        assert scale["status"] == "not applicable" and "does not stand out" in scale["reason"]
