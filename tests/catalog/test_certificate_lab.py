"""Certificates a lab can sign (issue 33 part 4, ISO/IEC 17025:2017 7.8): a verification alone is
refused; `--revise` only for the same item, listing what changed and keeping earlier corrections;
a second certificate of the same sessions warns naming the first; the approval writes the final
read-only document, an audit entry and a catalog record; `station certificates` and the web list
them wherever they were written (SQLite, and the shared PostgreSQL catalog); SIMULATION and
traceability never contradict the instrument; no placeholder; the whole budget; the spec by id.
Real session files, real catalog, the PDF read back with pdftotext."""

from __future__ import annotations

import hashlib
import json
import shutil
import stat
import subprocess

import numpy as np
import pytest
import sqlalchemy as sa

from drivers.plant.leg import default_leg_configs
from station.cli import main
from procedures.synthetic import synth_session
from tests.tooling import write_identified_session

TOL = {"HX300": {"as_found_um": {"E": 25.0, "B": 6.0, "R": 3.0}, "as_left_um": {"E": 3.0}, "source": "recorded",
                 "spec": "HX-SPEC-300", "spec_revision": "C"}}
CAL, VER = {"kind": "iso230", "overrun_mm": 2.0}, {"kind": "verification", "overrun_mm": 2.0}
LAB = ('[lab]\nname = "Hexapod Metrology Lab"\naddress = "Werkstr. 5, Musterstadt"\naccreditation = "D-K-12345-01-00"\n'
       'customer = "ACME"\ncustomer_contact = "J. Doe, qa@acme.example"\nauthoriser = "Dr. A. Weber"\n'
       'authoriser_role = "Head of laboratory"\n'
       '[tolerances.HX300]\nspec = "HX-SPEC-300"\nspec_revision = "C"\nE_um = 25.0\nB_um = 6.0\nR_um = 3.0\n'
       '[tolerances.HX300.as_left]\nE_um = 3.0\n')


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    d = tmp_path_factory.mktemp("lab")
    targets = np.linspace(-90.0, 90.0, 11)
    found = synth_session({1: default_leg_configs(0)[0]}, targets, cycles=5, seed=1)
    left = synth_session({1: default_leg_configs(0)[0]}, targets, cycles=5, seed=2)
    left["error_um"] = 0.1 * (left["error_um"] - left["error_um"].mean())  # as if compensated
    real = {"tolerances": TOL, "metrology": {"calibration_certificate": "LC-1234/2026, DAkkS D-K-15000-01-00"}}

    def w(name, pts, plan, day, **kw):
        return write_identified_session(d / name, pts, plan=plan, station_config=real,
                                        started_utc=f"2026-11-{day}T08:00:00.000000Z", **kw)

    return {"cal": w("cal.h5", found, CAL, "20", rig="live", devices={"interferometer": "LI-6 s/n SIM-0001"}),
            "ver": w("ver.h5", left, VER, "21", rig="live", devices={"interferometer": "LI-6 s/n SIM-0001"}),
            "sim_cal": w("sim-cal.h5", found, CAL, "20"),
            "other": w("other.h5", found, CAL, "20", rig="live", serial="HX-0002"),
            "wrong_laser": w("wrong-laser.h5", found, CAL, "20", rig="live",
                             devices={"interferometer": "LI-6 s/n 99999"})}


@pytest.fixture
def cfg(tmp_path):
    p = tmp_path / "station.toml"
    p.write_text(f'[station]\nrecordings_dir = "{tmp_path / "runs"}"\nid = "bench-1"\n' + LAB)
    return p


def _run(capsys, *argv) -> tuple[int, str, str]:
    rc = main([*map(str, argv)])
    out, err = capsys.readouterr()
    return rc, out, err


def _text(pdf) -> list[str]:
    """The PDF's pages as text (pdftotext), so what the reader sees is checked, not the JSON."""
    if shutil.which("pdftotext") is None:
        pytest.skip("poppler-utils not installed: apt-get install poppler-utils")
    out = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], capture_output=True, text=True, check=True).stdout
    return [p for p in out.split("\f") if p.strip()]


def _one_line_refusal(rc, err, *words):
    assert rc == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    for w in words:
        assert w in err, err


def test_a_verification_alone_is_refused(sessions, cfg, tmp_path, capsys):
    rc, out, err = _run(capsys, "certificate", sessions["ver"], "--config", cfg)
    _one_line_refusal(rc, err, "ver.h5: a verification session (as left)", "--as-left ver.h5")
    assert not (tmp_path / "runs" / "certificate-counter.json").exists()  # no number used up
    assert not (tmp_path / "runs" / "certificates").exists()
    # the as-left measured before the as-found calibration is no as-left
    rc, _, err = _run(capsys, "certificate", sessions["cal"], "--as-left", sessions["sim_cal"], "--config", cfg,
                      "--leg", "1")
    assert rc == 0, err  # the same day: not before
    early = write_identified_session(tmp_path / "early.h5", synth_session({1: default_leg_configs(0)[0]},
                                     np.linspace(-90.0, 90.0, 6), cycles=2), plan=VER,
                                     started_utc="2026-11-01T08:00:00.000000Z")
    rc, _, err = _run(capsys, "certificate", sessions["cal"], "--as-left", early, "--config", cfg)
    _one_line_refusal(rc, err, "early.h5 was measured", "before")


def test_second_issue_warns_naming_the_first_wherever_written(sessions, cfg, tmp_path, capsys):
    rc, out, err = _run(capsys, "certificate", sessions["cal"], "--as-left", sessions["ver"], "--config", cfg)
    assert rc == 0 and "already certified" not in out, err
    first = out.split()[1]
    elsewhere = tmp_path / "elsewhere"
    rc, out, err = _run(capsys, "certificate", sessions["cal"], "--as-left", sessions["ver"], "--config", cfg,
                        "--out", elsewhere)
    assert rc == 0, err
    warning = [ln for ln in out.splitlines() if ln.startswith("warning: these sessions are already certified")]
    assert len(warning) == 1 and f"{first} revision 1" in warning[0] and "_r1.pdf" in warning[0]
    # the other folder knows nothing of the first: the catalog named it; and the list shows both
    rc, out, _ = _run(capsys, "certificates", "--config", cfg, "--serial", "HX-0042")
    listed = [ln for ln in out.splitlines() if ln.startswith("bench-1-")]
    assert rc == 0 and len(listed) == 2 and all("HX-0042" in ln for ln in listed)
    assert str(elsewhere) in listed[1] and "2 certificate revision(s)" in out
    # the as-found alone is other sessions: no warning
    rc, out, _ = _run(capsys, "certificate", sessions["cal"], "--config", cfg)
    assert rc == 0 and "already certified" not in out


def test_revise_only_the_same_item_lists_changes_and_keeps_corrections(sessions, cfg, tmp_path, capsys):
    rc, _, err = _run(capsys, "certificate", sessions["cal"], "--config", cfg, "--received", "18.11.2026")
    _one_line_refusal(rc, err, "argument --received: '18.11.2026' is not a date; give it as YYYY-MM-DD")
    rc, out, err = _run(capsys, "certificate", sessions["cal"], "--as-left", sessions["ver"], "--config", cfg,
                        "--received", "2026-11-18")
    assert rc == 0, err
    number = out.split()[1]
    folder = tmp_path / "runs" / "certificates"
    index_before = (folder / f"{number}.index.json").read_bytes()
    files_before = sorted(p.name for p in folder.iterdir())
    rc, _, err = _run(capsys, "certificate", sessions["other"], "--config", cfg, "--revise", number, "--reason", "leg")
    _one_line_refusal(rc, err, f"--revise {number}: that certificate is of serial HX-0042",
                      "these sessions measured serial HX-0002")
    assert (folder / f"{number}.index.json").read_bytes() == index_before
    assert sorted(p.name for p in folder.iterdir()) == files_before
    # revision 2 corrects the customer; revision 3 (another reason) keeps that correction
    rc, out, err = _run(capsys, "certificate", sessions["cal"], "--as-left", sessions["ver"], "--config", cfg,
                        "--revise", number, "--reason", "customer corrected", "--customer", "ACME GmbH")
    assert rc == 0 and "1 field(s) changed" in out, out + err
    r2 = json.loads((folder / f"{number}_r2.json").read_text())
    assert r2["supersedes"]["changes"] == [{"field": "customer", "before": "ACME", "after": "ACME GmbH"}]
    text = "\n".join(_text(folder / f"{number}_r2.pdf"))
    assert "Changes from revision 1" in text and "ACME GmbH" in text and "customer corrected" in text
    rc, out, err = _run(capsys, "certificate", sessions["cal"], "--config", cfg, "--revise", number,
                        "--reason", "as left withdrawn")
    assert rc == 0, err
    r3 = json.loads((folder / f"{number}_r3.json").read_text())
    assert r3["customer"] == "ACME GmbH" and r3["customer_contact"] == "J. Doe, qa@acme.example"
    assert r3["item"]["received"] == "2026-11-18"
    assert any(ch["field"].startswith("as_left") and ch["after"] == "none" for ch in r3["supersedes"]["changes"])


def test_approval_writes_the_final_document_audit_and_catalog(sessions, cfg, tmp_path, capsys):
    rc, out, err = _run(capsys, "certificate", sessions["cal"], "--as-left", sessions["ver"], "--config", cfg)
    assert rc == 0, err
    number = out.split()[1]
    folder = tmp_path / "runs" / "certificates"
    draft = folder / f"{number}_r1.pdf"
    draft_bytes = draft.read_bytes()
    pages = _text(draft)
    assert all("DRAFT: not valid until approved" in p for p in pages)
    assert "NOT YET APPROVED. To be approved by Dr. A. Weber, Head of laboratory" in "\n".join(pages)
    rc, _, err = _run(capsys, "certificate", "approve", number, "--by", "Someone Else", "--config", cfg)
    _one_line_refusal(rc, err, "--by 'Someone Else'", "'Dr. A. Weber'")
    rc, _, err = _run(capsys, "certificate", "approve", "bench-1-20000101-0042", "--by", "Dr. A. Weber", "--config", cfg)
    _one_line_refusal(rc, err, "no certificate bench-1-20000101-0042")
    rc, out, err = _run(capsys, "certificate", "approve", number, "--by", "Dr. A. Weber", "--config", cfg)
    assert rc == 0, err
    final = folder / f"{number}_r1_approved.pdf"
    assert stat.S_IMODE(final.stat().st_mode) & 0o222 == 0 and draft.read_bytes() == draft_bytes
    pages = _text(final)
    text = "\n".join(pages)
    assert not any("DRAFT" in p for p in pages)
    assert "Approved by" in text and "Dr. A. Weber, Head of laboratory" in text
    (entry,) = [json.loads(ln) for ln in (tmp_path / "runs" / "audit.jsonl").read_text().splitlines()]
    assert entry["action"] == "approve" and entry["details"]["report_no"] == number and entry["operator"] == "Dr. A. Weber"
    assert entry["details"]["sha256_pdf"] == hashlib.sha256(final.read_bytes()).hexdigest()
    assert entry["id"] in text  # the document names its audit entry
    index = json.loads((folder / f"{number}.index.json").read_text())
    assert index["revisions"][0]["status"] == "approved" and index["revisions"][0]["audit_id"] == entry["id"]
    engine = sa.create_engine(f"sqlite:///{tmp_path / 'runs' / 'catalog.sqlite'}")
    with engine.connect() as conn:
        rows = conn.execute(sa.text("SELECT outcome, sha256, path FROM records WHERE kind = 'certificate' "
                                    "ORDER BY time_utc")).all()
    engine.dispose()
    assert [r[0] for r in rows] == ["draft", "approved"]
    assert rows[1][1] == entry["details"]["sha256_pdf"] and rows[1][2] == str(final)
    rc, out, _ = _run(capsys, "certificates", "--config", cfg)
    assert rc == 0 and "approved" in out and "Dr. A. Weber" in out and str(final) in out
    # never twice; and the catalog's `check` knows the file by its sha256
    rc, _, err = _run(capsys, "certificate", "approve", number, "--by", "Dr. A. Weber", "--config", cfg)
    _one_line_refusal(rc, err, "already approved by Dr. A. Weber")


def test_real_measurement_traceable_simulated_marked_and_not_accredited(sessions, cfg, tmp_path, capsys):
    folder = tmp_path / "runs" / "certificates"
    assert _run(capsys, "certificate", sessions["cal"], "--as-left", sessions["ver"], "--config", cfg)[0] == 0
    (real,) = folder.glob("*_r1.pdf")
    text = "\n".join(_text(real))
    assert "traceable to the SI unit of length, the metre, through the laser interferometer LI-6 serial SIM-0001" in text
    assert "LC-1234/2026" in text and "D-K-12345-01-00" in text and "SIMULATION" not in text
    # a placeholder never reaches the reader; the spec by its identifier; every budget source
    assert "overrun_mm" not in text and "2 mm beyond its first target" in text
    assert "HX-SPEC-300 revision C" in text and "[tolerances." not in text and ".toml" not in text
    assert "see JSON" not in text and "Deviation graph as found" in text and "Deviation graph as left" in text
    flat = " ".join(text.split())
    # every source in the budget tables, a zero one with its reason (cells wrap: words, not lines)
    for words in ("misalignment", "[metrology] misalignment_mm = 0", "Abbe", "abbe_offset_mm = 0", "dead path",
                  "dead_path_mm = 0", "laser 0.25 ppm", "repeatability", "combined u_c", "U (k = 2)"):
        assert words in flat, words
    (j,) = folder.glob("*_r1.json")
    rows = {r["source"]: r for r in json.loads(j.read_text())["as_found"]["budget"]["rows"]}
    assert rows["misalignment"]["zero_because"].startswith("[metrology] misalignment_mm = 0")
    assert rows["laser"]["u_um"]["E"] > 0 and "zero_because" not in rows["laser"]
    real.rename(real.with_suffix(".seen"))

    rc, out, err = _run(capsys, "certificate", sessions["sim_cal"], "--config", cfg)
    assert rc == 0 and "warning: SIMULATION" in out, err
    (sim,) = folder.glob("*_r1.pdf")
    pages = _text(sim)
    assert len(pages) >= 2 and all("SIMULATION: not a calibration of a real item" in p for p in pages)
    text = "\n".join(pages)
    assert "D-K-12345-01-00" not in text and "traceable to the SI unit of length, the metre" not in text
    assert "NOT TRACEABLE" in text
    sim.rename(sim.with_suffix(".seen"))

    # the laser connected is not the one whose calibration is stated: never "traceable" under that box
    rc, out, err = _run(capsys, "certificate", sessions["wrong_laser"], "--config", cfg)
    assert rc == 0, err
    (wrong,) = folder.glob("*_r1.pdf")
    text = " ".join(" ".join(_text(wrong)).split())
    assert "CHECK THE INSTRUMENT" in text and "NOT TRACEABLE" in text
    assert "results are traceable to the SI" not in text


def test_certificates_in_the_shared_postgresql_catalog_and_on_the_web(sessions, tmp_path, capsys, pg_url):
    from fastapi.testclient import TestClient

    from station.web.app import WebSettings, create_app
    from station.web.engine import open_readonly

    cfg = tmp_path / "station.toml"
    cfg.write_text(f'[station]\nrecordings_dir = "{tmp_path / "runs"}"\nid = "bench-1"\n[catalog]\nurl = "{pg_url}"\n'
                   + LAB)
    elsewhere = tmp_path / "outside"
    rc, out, err = _run(capsys, "certificate", sessions["cal"], "--config", cfg, "--out", elsewhere)
    assert rc == 0, err
    number = out.split()[1]
    rc, out, err = _run(capsys, "certificate", "approve", number, "--by", "Dr. A. Weber", "--config", cfg,
                        "--out", elsewhere)
    assert rc == 0, err
    rc, out, _ = _run(capsys, "certificates", "--catalog", pg_url, "--config", cfg)
    assert rc == 0 and number in out and "approved" in out and str(elsewhere) in out
    client = TestClient(create_app(open_readonly(pg_url), WebSettings(where="catalog: test")))
    page = client.get("/certificates")
    assert page.status_code == 200 and number in page.text and "Dr. A. Weber" in page.text
    assert str(elsewhere / f"{number}_r1_approved.pdf") in page.text
    assert "/certificates" in client.get("/").text  # in the navigation
    page = client.get("/certificates", params={"serial": "HX-0099"})
    assert page.status_code == 200 and number not in page.text and 'id="no-certificates"' in page.text
    assert client.get("/certificates", params={"serial": "../x"}).status_code == 400
    # the approved PDF itself, as indexed; an unknown or malformed sha256 is no file
    final = elsewhere / f"{number}_r1_approved.pdf"
    sha = hashlib.sha256(final.read_bytes()).hexdigest()
    got = client.get(f"/certificates/pdf/{sha}")
    assert got.status_code == 200 and got.content == final.read_bytes()
    assert client.get(f"/certificates/pdf/{'0' * 64}").status_code == 404
    assert client.get("/certificates/pdf/..%2F..%2Fetc").status_code in (400, 404)
