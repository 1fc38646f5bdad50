"""The stage of sessions written before schema 1.2 (no root `stage`): derived from what the file
recorded, so `station catalog rebuild` classifies older files; and the stage a new file records
wins over the derivation."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import sqlalchemy as sa

from procedures.io.recording.reader import read_session
from procedures.io.recording.writer import SessionWriter
from station.cli import main
from tests.catalog.helpers import identity, stamp_identity
from tests.tooling import default_legs_points

ACTIVE = json.dumps({"target": "drive", "enabled": True, "bank": 1, "points": 31, "sha256": "ab" * 32,
                     "start_mm": -90.0, "spacing_mm": 6.0})
EMPTY = json.dumps({"target": "drive", "enabled": True, "bank": 0, "points": 0, "sha256": ""})


def _old_session(path: Path, plan_kind: str, devices: dict, started: str, rig: str = "sim") -> Path:
    with SessionWriter.create(path, session_id=path.stem, operator="t", rig=rig, plan={"kind": plan_kind},
                              station_config={}, devices=devices, software_version="t", started_utc=started) as w:
        w.append_points(default_legs_points([1], 2, 15.0, 0))
        w.finish("completed")
    with h5py.File(path, "a") as f:  # as a 1.1 file was written: no stage
        del f.attrs["stage"]
        f.attrs["schema_version"] = "1.1"
    stamp_identity(path, identity({1: "HX-OLD"}))
    return path


def test_rebuild_classifies_files_without_a_stage(tmp_path, capsys):
    runs = tmp_path / "runs"
    runs.mkdir()
    files = {
        "as_found": _old_session(runs / "cal.h5", "iso230", {"leg1_compensation_table": EMPTY}, "2026-01-01T08:00:00Z"),
        "as_left": _old_session(runs / "ver.h5", "verification", {"leg1_compensation_table": ACTIVE},
                                "2026-01-01T09:00:00Z"),
        "other": _old_session(runs / "comp.h5", "iso230", {"leg1_compensation_table": ACTIVE}, "2026-01-01T10:00:00Z"),
        # a file from before the JSON record: the text one names the active table
        "other_text": _old_session(runs / "comp-old.h5", "iso230", {
            "leg1_compensation": "bank 1 active, 31 points from -90.000 mm every 6 mm"}, "2026-01-01T11:00:00Z"),
        "replay": _old_session(runs / "r.h5", "iso230", {}, "2026-01-01T12:00:00Z", rig="replay"),
    }
    assert {k: read_session(p).stage for k, p in files.items()} == {
        "as_found": "as_found", "as_left": "as_left", "other": "other", "other_text": "other", "replay": "other"}
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[station]\nrecordings_dir = "{runs}"\n')
    assert main(["catalog", "rebuild", "--config", str(cfg)]) == 0
    capsys.readouterr()
    engine = sa.create_engine(f"sqlite:///{runs / 'catalog.sqlite'}")
    with engine.connect() as conn:
        got = dict(conn.execute(sa.text("SELECT path, stage FROM records WHERE kind = 'session'")).all())
        legs = dict(conn.execute(sa.text("SELECT uid, stage FROM record_legs")).all())
    engine.dispose()
    assert {Path(p).name: s for p, s in got.items()} == {
        "cal.h5": "as_found", "ver.h5": "as_left", "comp.h5": "other", "comp-old.h5": "other", "r.h5": "other"}
    assert sorted(legs.values()) == sorted(got.values())
    assert main(["history", "HX-OLD", "--config", str(cfg)]) == 0
    out = capsys.readouterr().out
    assert "1 calibration(s) as found, 1 verification(s) as left" in out
    assert main(["catalog", "status", "--config", str(cfg), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["stages"] == {"as_found": 1, "as_left": 1, "other": 3}


def test_the_recorded_stage_wins(tmp_path):
    path = tmp_path / "s.h5"
    with SessionWriter.create(path, session_id="s", operator="t", rig="sim", plan={"kind": "iso230"},
                              station_config={}, devices={"leg1_compensation_table": ACTIVE}, software_version="t") as w:
        w.append_points(default_legs_points([1], 2, 15.0, 0))
        w.finish("completed")
    s = read_session(path)
    assert s.attrs["stage"] == "other" and s.schema_version == "1.2"
    with h5py.File(path, "a") as f:
        f.attrs["stage"] = "as_left"  # what the file says is what it is
    assert read_session(path).stage == "as_left"
