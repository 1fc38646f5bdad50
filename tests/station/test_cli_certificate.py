"""`station certificate`: a numbered, immutable certificate (PDF + JSON) of one leg; a revision
keeps the old files and marks them superseded; the PDF is valid, paged "x of y", and renders."""

from __future__ import annotations

import json
from pathlib import Path
import os
import shutil
import stat
import subprocess

import numpy as np
import pytest

from drivers.plant.leg import default_leg_configs
from station.cli import main
from procedures.synthetic import synth_session
from tests.tooling import lab_config, write_identified_session

TOL = {"HX300": {"as_found_um": {"E": 25.0, "B": 6.0, "R": 3.0}, "as_left_um": {"E": 0.001}, "source": "recorded"}}


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    d = tmp_path_factory.mktemp("cert")
    targets = np.linspace(-90.0, 90.0, 11)
    found = synth_session({1: default_leg_configs(0)[0]}, targets, cycles=5, seed=1)
    left = synth_session({1: default_leg_configs(0)[0]}, targets, cycles=5, seed=2)
    left["error_um"] = 0.1 * (left["error_um"] - left["error_um"].mean())  # as if compensated
    return {"found": write_identified_session(d / "cal.h5", found, station_config={"tolerances": TOL}),
            "left": write_identified_session(d / "ver.h5", left, station_config={"tolerances": TOL}),
            "untraced": write_identified_session(d / "old.h5", found, calibration_due=None),
            "other": write_identified_session(d / "other.h5", left, serial="HX-0099")}


@pytest.fixture
def cfg(tmp_path):
    return lab_config(tmp_path)


def _issue(capsys, *argv) -> tuple[int, str, str]:
    rc = main(["certificate", *map(str, argv)])
    out, err = capsys.readouterr()
    return rc, out, err


def _written_json(out: str) -> Path:
    """The certificate JSON a run printed ("wrote X.json"); never a glob of the folder, whose order
    is the file system's and which also holds the number index."""
    (line,) = [ln for ln in out.splitlines() if ln.startswith("wrote ") and ln.endswith(".json")]
    return Path(line[len("wrote "):])


def test_certificate_content_numbering_and_revision(sessions, cfg, tmp_path, capsys):
    table = tmp_path / "table.csv"
    from procedures.compensation.table import CompTable, LegTable, table_csv_text

    zeros = tuple(0.0 for _ in range(31))
    table.write_text(table_csv_text(CompTable({1: LegTable(1, -90.0, 6.0, zeros, zeros)})))
    rc, out, _ = _issue(capsys, sessions["found"], "--as-left", sessions["left"], "--table", table, "--config", cfg)
    assert rc == 0
    folder = tmp_path / "runs" / "certificates"
    (first,) = sorted(folder.glob("*_r1.json"))
    c = json.loads(first.read_text())
    day = c["issued_utc"][:10].replace("-", "")
    assert c["report_no"] == f"bench-1-{day}-0001" and c["revision"] == 1
    assert c["laboratory"]["name"] == "Hexapod Metrology Lab" and c["customer"] == "ACME"
    assert c["item"]["serial"] == "HX-0042" and c["item"]["leg_type"] == "HX300"
    assert c["instrument"]["traceable"] is True and c["instrument"]["model"] == "LI-6"
    assert c["compensation_table"]["sha256"] == __import__("hashlib").sha256(table.read_bytes()).hexdigest()
    # the synthetic as-left session recorded no active table: no match claimed
    assert c["compensation_table"]["matches_as_left"] is None
    # as found: decided against the as-found limits; as left: E held to 0.001 um cannot be met
    assert c["as_found"]["values"]["E"]["limit_um"] == 25.0 and c["as_found"]["values"]["E"]["U_um"] > 0
    assert c["as_left"]["values"]["E"]["decision"] == "does not conform"
    rows = c["as_found"]["targets"]
    assert len(rows) == 11
    for r in rows:  # B_i per target is x_up - x_down of the same target
        assert r["B_i_um"] == pytest.approx(r["x_up_um"] - r["x_down_um"])
    # a second certificate takes the next number, never the same
    assert _issue(capsys, sessions["found"], "--config", cfg)[0] == 0
    assert (folder / f"bench-1-{day}-0002_r1.pdf").exists()
    # a revision: the old files stay unchanged, the index marks revision 1 superseded by 2
    before = (folder / f"bench-1-{day}-0001_r1.pdf").read_bytes()
    assert _issue(capsys, sessions["found"], "--config", cfg, "--revise", c["report_no"])[0] == 2  # no --reason
    rc, out, _ = _issue(capsys, sessions["found"], "--as-left", sessions["left"], "--config", cfg,
                        "--revise", c["report_no"], "--reason", "customer address corrected")
    assert rc == 0 and "supersedes revision 1" in out
    assert (folder / f"bench-1-{day}-0001_r1.pdf").read_bytes() == before
    index = json.loads((folder / f"bench-1-{day}-0001.index.json").read_text())
    assert [(r["revision"], r["status"]) for r in index["revisions"]] == [(1, "superseded"), (2, "issued")]
    assert index["revisions"][0]["superseded_by"] == 2
    r2 = json.loads((folder / f"bench-1-{day}-0001_r2.json").read_text())
    assert r2["supersedes"]["revision"] == 1 and r2["supersedes"]["reason"] == "customer address corrected"
    assert stat.S_IMODE((folder / f"bench-1-{day}-0001_r1.pdf").stat().st_mode) & 0o222 == 0  # read-only
    # the counter went on: a new certificate is 0003
    assert _issue(capsys, sessions["found"], "--config", cfg)[0] == 0
    assert (folder / f"bench-1-{day}-0003_r1.json").exists()


def test_not_traceable_is_stated_loudly(sessions, cfg, tmp_path, capsys):
    rc, out, _ = _issue(capsys, sessions["untraced"], "--config", cfg)
    assert rc == 0 and "NOT TRACEABLE" in out
    (j,) = (tmp_path / "runs" / "certificates").glob("*_r1.json")
    c = json.loads(j.read_text())
    assert c["instrument"]["traceable"] is False and c["instrument"]["warnings"]
    # no tolerances recorded for this session: no decision, said so
    assert c["as_found"]["overall"] == "no tolerance stated"


def test_as_left_of_another_leg_refused(sessions, cfg, tmp_path, capsys):
    rc, _, err = _issue(capsys, sessions["found"], "--as-left", sessions["other"], "--config", cfg)
    assert rc == 2 and "other.h5 measured leg HX-0099" in err and "cal.h5 measured leg HX-0042" in err
    assert not list((tmp_path / "runs" / "certificates").glob("*.pdf"))


def test_as_left_found_by_serial_when_the_leg_was_remounted(sessions, cfg, tmp_path, capsys):
    """Calibrated at position 1, verified at position 3 (the same serial): the certificate pairs
    them by serial and states where each session measured the leg."""
    from procedures.io.recording.reader import read_session

    left = read_session(sessions["left"]).points.copy()
    left["leg"] = 3
    moved = write_identified_session(tmp_path / "ver-at-3.h5", left, station_config={"tolerances": TOL})
    rc, out, err = _issue(capsys, sessions["found"], "--as-left", moved, "--config", cfg)
    assert rc == 0, err
    # the certificate the command says it wrote: the folder also holds the number index (.index.json)
    c = json.loads(_written_json(out).read_text())
    assert c["item"]["serial"] == "HX-0042" and c["item"]["leg"] == 1
    assert c["as_found"]["leg"] == 1 and c["as_left"]["leg"] == 3
    assert c["as_left"]["session_file"] == "ver-at-3.h5"
    # two positions carrying the one serial: which is the leg is not for the certificate to guess
    both = read_session(sessions["left"]).points.copy()
    both = np.concatenate([both, both])
    both["leg"][: len(both) // 2] = 2
    both["leg"][len(both) // 2 :] = 3
    both["index"] = np.arange(len(both))
    twice = write_identified_session(tmp_path / "ver-twice.h5", both)
    rc, _, err = _issue(capsys, sessions["found"], "--as-left", twice, "--config", cfg)
    assert rc == 2 and "legs [2, 3] all carry serial HX-0042" in err


def test_several_legs_need_leg(cfg, tmp_path, capsys):
    from tests.tooling import default_legs_points

    s = write_identified_session(tmp_path / "two.h5", default_legs_points(legs=(1, 2), cycles=2, step_mm=30.0))
    rc, _, err = _issue(capsys, s, "--config", cfg)
    assert rc == 2 and "holds legs [1, 2]" in err and "--leg" in err
    rc, out, _ = _issue(capsys, s, "--config", cfg, "--leg", "2")
    assert rc == 0 and "leg 2 serial HX-0042" in out


def test_a_leg_without_serial_is_refused(cfg, tmp_path, capsys):
    from tests.tooling import write_points_session

    s = write_points_session(tmp_path / "anon.h5", synth_session({1: default_leg_configs(0)[0]},
                                                                 np.linspace(-90.0, 90.0, 6), cycles=2))
    rc, _, err = _issue(capsys, s, "--config", cfg)
    assert rc == 2 and "anon.h5: leg 1 has no serial recorded" in err
    assert not (tmp_path / "runs" / "certificate-counter.json").exists()  # no number used up


def test_pdf_is_valid_paged_and_renders(sessions, cfg, tmp_path, capsys):
    assert _issue(capsys, sessions["found"], "--as-left", sessions["left"], "--config", cfg)[0] == 0
    (pdf,) = (tmp_path / "runs" / "certificates").glob("*_r1.pdf")
    data = pdf.read_bytes()
    assert data.startswith(b"%PDF-") and b"%%EOF" in data[-64:]
    if shutil.which("pdftotext") is None or shutil.which("pdftoppm") is None:
        if os.environ.get("CI") == "true":
            pytest.fail("poppler-utils (pdftotext, pdftoppm) missing under CI=true")
        pytest.skip("poppler-utils not installed: apt-get install poppler-utils")
    text = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], capture_output=True, text=True, check=True).stdout
    pages = text.count("\f")
    assert pages >= 2
    for i in range(1, pages + 1):
        assert f"Page {i} of {pages}" in text
    from procedures.reporting.certificate import DEJAVU

    if (DEJAVU / "DejaVuSans.ttf").exists():  # Unicode units with Debian's fonts-dejavu-core, else ASCII
        assert "µm" in text and "°C" in text and " um" not in text
    else:
        assert "um" in text and "degC" in text
    assert "End of certificate" in text
    subprocess.run(["pdftoppm", "-r", "40", "-png", str(pdf), str(tmp_path / "page")], check=True)
    assert len(list(tmp_path.glob("page*.png"))) == pages
