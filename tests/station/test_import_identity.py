"""Imports with identity (issue 33 part 5): serial, part number, type, stage, station, date and
laser given by options, the map's [identity] or --config, recorded in the session, so an imported
session is decided and certified like a recorded one; refusals in one line, nothing written.
Real files: the sample map and CSV of docs/import-maps, read back as sessions."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from procedures.io.recording.reader import read_session
from station.cli import main
from station.services.certificate_jobs import session_stage

MAPS = Path(__file__).resolve().parents[2] / "docs" / "import-maps"
CSV, MAP = MAPS / "renishaw-like.csv", MAPS / "renishaw-like.toml"


@pytest.fixture
def cfg(tmp_path):
    p = tmp_path / "station.toml"
    p.write_text(f'[station]\nrecordings_dir = "{tmp_path / "runs"}"\nid = "lab-2"\n'
                 '[lab]\nname = "Lab"\nauthoriser = "Dr. A. Weber"\n'
                 '[tolerances.HX300]\nspec = "HX-SPEC-300"\nspec_revision = "C"\nE_um = 25.0\nB_um = 6.0\n')
    return p


def _run(capsys, *argv):
    rc = main([*map(str, argv)])
    out, err = capsys.readouterr()
    return rc, out, err


def _map_with_identity(tmp_path, **identity) -> Path:
    body = MAP.read_text() + "\n[identity]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in identity.items())
    p = tmp_path / "with-identity.toml"
    p.write_text(body)
    return p


def test_options_give_an_import_its_identity_and_it_is_certified(cfg, tmp_path, capsys):
    out_h5 = tmp_path / "imp.h5"
    rc, out, err = _run(capsys, "import", CSV, "--map", MAP, "--out", out_h5, "--serial", "HX-0042",
                        "--part-number", "HX-L-300", "--leg-type", "HX300", "--stage", "calibration",
                        "--measured", "2026-11-20T09:30", "--config", cfg)
    assert rc == 0, err
    assert "identity: leg 1 HX-0042 type HX300; station lab-2; stage calibration" in out
    s = read_session(out_h5)
    li = s.identity.leg(1)
    assert (li.serial, li.part_number, li.leg_type) == ("HX-0042", "HX-L-300", "HX300")
    assert s.identity.station.id == "lab-2" and s.attrs["started_utc"].startswith("2026-11-20T09:30:00")
    assert session_stage(s) == "calibration"
    rc, out, err = _run(capsys, "certificate", out_h5, "--config", cfg)
    assert rc == 0, err
    assert "as found conforms" in out or "as found cannot decide" in out or "as found does not conform" in out
    (j,) = (tmp_path / "runs" / "certificates").glob("*_r1.json")
    c = json.loads(j.read_text())
    assert c["item"]["serial"] == "HX-0042" and c["item"]["leg_type"] == "HX300"
    assert c["method"]["specification"] == "HX-SPEC-300 revision C"
    assert c["as_found"]["started_utc"].startswith("2026-11-20T09:30") and not c["simulated"]


def test_the_map_identity_a_verification_and_the_pair_certified(cfg, tmp_path, capsys):
    cal, ver = tmp_path / "cal.h5", tmp_path / "ver.h5"
    m = _map_with_identity(tmp_path, serial="HX-0042", part_number="HX-L-300", leg_type="HX300", station="lab-9",
                           stage="calibration", measured_utc="2026-11-20", laser_model="XL-80",
                           laser_serial="L-77", laser_calibrated_on="2026-01-10", laser_calibration_due="2027-01-10")
    assert _run(capsys, "import", CSV, "--map", m, "--out", cal, "--config", cfg)[0] == 0
    # the options win over the map: the same file as the verification a day later
    rc, out, err = _run(capsys, "import", CSV, "--map", m, "--out", ver, "--stage", "verification",
                        "--measured", "2026-11-21", "--config", cfg)
    assert rc == 0, err
    s = read_session(ver)
    assert session_stage(s) == "verification" and s.identity.station.id == "lab-9"
    assert s.identity.instrument.serial == "L-77" and s.identity.instrument.traceable
    # a verification alone is refused; as the as-left of the calibration it is certified, decided as left
    rc, _, err = _run(capsys, "certificate", ver, "--config", cfg)
    assert rc == 2 and "a verification session (as left)" in err and len(err.strip().splitlines()) == 1
    rc, out, err = _run(capsys, "certificate", cal, "--as-left", ver, "--config", cfg)
    assert rc == 0, err
    (j,) = (tmp_path / "runs" / "certificates").glob("*_r1.json")
    c = json.loads(j.read_text())
    assert c["as_left"]["stage"] == "as_left" and c["as_left"]["kind"] == "as-left verification"
    assert c["instrument"]["serial"] == "L-77" and c["traceability"]["traceable"] is True


def test_an_import_without_stage_is_not_certified(cfg, tmp_path, capsys):
    out_h5 = tmp_path / "bare.h5"
    rc, out, _ = _run(capsys, "import", CSV, "--map", MAP, "--out", out_h5, "--serial", "HX-0042")
    assert rc == 0 and "stage not stated (other)" in out
    assert session_stage(read_session(out_h5)) == "other"
    rc, _, err = _run(capsys, "certificate", out_h5, "--config", cfg)
    assert rc == 2 and "re-import it with --stage calibration" in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("extra, message", [
    (("--serial", "3=HX-0042"), "--serial 3=...: the file holds legs [1], not leg 3"),
    (("--stage", "adjusted"), "argument --stage: invalid choice: 'adjusted' (choose from 'calibration', 'verification', 'other')"),
    (("--measured", "20.11.2026"), "argument --measured: '20.11.2026' is not a date or time; give YYYY-MM-DD"),
    (("--serial", "HX 42/../x"), "--serial"),
])
def test_bad_identity_options_are_refused_and_nothing_written(tmp_path, capsys, extra, message):
    out_h5 = tmp_path / "x.h5"
    rc, _, err = _run(capsys, "import", CSV, "--map", MAP, "--out", out_h5, *extra)
    assert rc == 2 and message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out_h5.exists()


def test_bad_map_identity_names_the_key(tmp_path, capsys):
    for identity, message in (({"stage": "later"}, "key identity.stage: 'later': one of calibration"),
                              ({"laser_calibration_due": "soon"}, "key identity.laser_calibration_due: 'soon': give a date"),
                              ({"serial": 42}, "key identity.serial: 42 must be a non-empty string")):
        m = _map_with_identity(tmp_path, **identity)
        rc, _, err = _run(capsys, "import", CSV, "--map", m, "--out", tmp_path / "y.h5")
        assert rc == 2 and message in err and len(err.strip().splitlines()) == 1, err
        assert not (tmp_path / "y.h5").exists()
    m = tmp_path / "unknown.toml"
    m.write_text(MAP.read_text() + '\n[identity]\ncustomer = "ACME"\n')
    rc, _, err = _run(capsys, "import", CSV, "--map", m, "--out", tmp_path / "y.h5")
    assert rc == 2 and "key identity.customer: unknown key" in err
