"""The ISO 230-2 report names the legs' serials, the station and the instrument with its
calibration state, and warns about a laser past its due date or without one (json, md, pdf)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from types import MappingProxyType

import pytest

from drivers.plant.leg import PlantConfig
from procedures.acquisition import plans
from procedures.io.recording.identity import (
    DriveIdentity,
    LegIdentity,
    SessionIdentity,
    StationIdentity,
    instrument_identity,
)
from procedures.reporting.session_report import make_report
from procedures.synthetic import synth_session

PLAN = plans.iso230_plan(legs=(1, 2))
ATTRS = {"session_id": "abc", "operator": "ana", "rig": "sim", "started_utc": "2026-11-24T08:00:00+00:00",
         "ended_utc": "2026-11-24T09:00:00+00:00", "outcome": "completed", "software_version": "1.2.3"}
METROLOGY = {"model": "Renishaw XL-80", "serial": "XL-12345", "calibration_date": "2025-10-01"}


def _identity(due: str | None) -> dict:
    legs = {leg: LegIdentity(f"HX-004{leg}", "HX-L-300", "HX300", "L7", DriveIdentity("V", "P", "1", f"D{leg}", "config"))
            for leg in (1, 2)}
    return SessionIdentity(StationIdentity("bench-a", "host-a"), "ana", "1.2.3",
                           instrument_identity("Renishaw XL-80", "XL-12345", due, "2025-10-01"),
                           MappingProxyType(legs)).to_json()


@pytest.fixture(scope="module")
def points():
    return synth_session({1: PlantConfig(), 2: PlantConfig()}, PLAN.targets_mm, cycles=5, seed=3)


def _report(points, out, identity):
    meta = {"plan": PLAN.to_dict(), "devices": {}, "station_config": {"metrology": METROLOGY}, "attrs": ATTRS,
            "identity": identity}
    return make_report(points, out, source_path="cal.h5", source_sha256="d" * 64, session_meta=meta).iso230


def _pdf_text(out) -> str | None:
    if shutil.which("pdftotext") is None:
        if os.environ.get("CI") == "true":
            pytest.fail("pdftotext (poppler-utils) is needed on CI to read the report's PDF")
        return None
    return subprocess.run(["pdftotext", "-layout", str(out / "iso230-2.pdf"), "-"], capture_output=True, text=True,
                          check=True).stdout


def test_past_due_laser_is_warned_in_every_report_file(points, tmp_path):
    # due 2026-11-01, the test ran on 2026-11-24: past due on the day of the measurement
    d = _report(points, tmp_path, _identity("2026-11-01"))
    ins = d["identification"]["instrument"]
    assert ins["calibration_due"] == "2026-11-01" and ins["traceable"] is False
    (warning,) = d["warnings"]
    assert "calibration was due 2026-11-01, 23 day(s) before 2026-11-24" in warning
    assert d["identification"]["station"] == {"id": "bench-a", "host": "host-a"}
    assert d["identification"]["leg_identity"]["2"]["serial"] == "HX-0042"
    assert json.loads((tmp_path / "iso230-2.json").read_text())["warnings"] == [warning]
    md = (tmp_path / "iso230-2.md").read_text()
    assert f"WARNING: {warning}." in md and "HX-0041" in md and "HX-0042" in md and "bench-a" in md
    assert "calibration due 2026-11-01: NOT traceable" in md
    text = _pdf_text(tmp_path)
    if text is not None:
        flat = " ".join(text.split())
        for phrase in ("WARNING", "2026-11-01", "NOT traceable", "HX-0041", "HX-0042", "bench-a", "XL-12345"):
            assert phrase in flat, phrase


def test_laser_in_calibration_on_the_day_of_the_test_is_traceable(points, tmp_path):
    # judged on the day of the measurement: due the day after the test, whatever today is
    d = _report(points, tmp_path, _identity("2026-11-25"))
    assert d["warnings"] == [] and d["identification"]["instrument"]["traceable"] is True
    assert "in calibration on the day of the test (traceable)" in (tmp_path / "iso230-2.md").read_text()


def test_a_session_without_identity_says_what_is_not_known(points, tmp_path):
    d = _report(points, tmp_path, {})
    assert d["warnings"] == ["Renishaw XL-80 s/n XL-12345: calibration due date not stated: result not traceable"]
    assert d["identification"]["leg_identity"]["1"]["serial"] == "not recorded"
    assert d["identification"]["station"]["id"] == "not recorded"
    assert d["identification"]["software_version"] == "1.2.3"  # the root attribute of a 1.0 file
