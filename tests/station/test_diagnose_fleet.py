"""`station diagnose --twin fleet:TYPE`: the legs of one type in the catalog as the twin, and how
many sigma a feature of this leg lies from its siblings. Real session files from the project's
generator (procedures.synthetic, the plant's leg-to-leg spread of default_leg_configs), indexed into a
real SQLite catalog by the catalog's own indexer."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest

from drivers.plant.leg import default_leg_configs
from procedures.diagnosis.fleet import error_map
from procedures.vocabulary import InputError
from procedures.io.recording.reader import read_session
from procedures.io.recording.writer import SessionWriter
from station.catalog import files
from station.catalog.fleet import completed_sessions_of_type
from station.catalog.store import Catalog
from station.cli import main
from procedures.synthetic import synth_session
from station.services.twins import load_twin
from tests.catalog.helpers import identity, stamp_identity

TYPE = "HX-L300"
TARGETS = np.linspace(-88.0, 88.0, 45)
CLEAN = 7  # clean legs; each has 6 clean siblings and the worn one


def _write(path, cfg, seed, serial, day, temperature=True):
    pts = synth_session({1: cfg}, TARGETS, cycles=3, seed=seed, dwell_s=1.0)
    if not temperature:
        pts["material_temp_c"] = np.nan
    with SessionWriter.create(path, session_id=path.stem, operator="test", rig="sim", plan={"kind": "test"},
                              station_config={}, devices={}, software_version="test",
                              started_utc=f"2026-01-{day:02d}T08:00:00.000000Z") as w:
        w.append_points(pts)
        w.finish("completed")
    stamp_identity(path, identity({1: serial}, leg_type=TYPE))
    return path


def _index(folder):
    catalog = Catalog(local=folder / "catalog.sqlite", station_id="ST-A")
    count, problems = files.index(catalog, [folder], forward=False)
    assert not problems
    config = folder / "station.toml"
    config.write_text(f'[station]\nid = "ST-A"\nrecordings_dir = "{folder}"\n')
    return catalog, config


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """CLEAN clean legs of one type (the plant's leg-to-leg spread in lead, long-wave, wobble,
    reversal, bearing) and one whose reversal is 1 um larger towards the top end of the stroke
    (nut wear over the last 30 mm)."""
    folder = tmp_path_factory.mktemp("fleet")
    cfgs = default_leg_configs(3, CLEAN + 1)
    paths = {}
    for i in range(CLEAN):
        paths[f"SN-{i}"] = _write(folder / f"leg{i}.h5", cfgs[i], i, f"SN-{i}", 10 + i)
    worn = replace(cfgs[CLEAN], reversal_wear_um=1.0, reversal_wear_centre_mm=90.0, reversal_wear_half_width_mm=30.0)
    paths["SN-W"] = _write(folder / "worn.h5", worn, CLEAN, "SN-W", 10 + CLEAN)
    catalog, config = _index(folder)
    return folder, paths, catalog, config


def test_the_catalog_lists_the_completed_sessions_of_a_type(fleet):
    _, paths, catalog, _ = fleet
    rows = completed_sessions_of_type(catalog.engine, TYPE)
    assert sorted(r.serial for r in rows) == sorted(paths)
    assert completed_sessions_of_type(catalog.engine, "OTHER") == []


def test_the_worn_leg_is_named_by_its_reversal_at_the_top_end(fleet, tmp_path, capsys):
    _, paths, _, config = fleet
    out = tmp_path / "d.json"
    assert main(["diagnose", str(paths["SN-W"]), "--twin", f"fleet:{TYPE}", "--config", str(config),
                 "--json", str(out)]) == 0
    text = capsys.readouterr().out
    rep = json.loads(out.read_text())
    assert rep["twin"]["kind"] == "fleet"
    fl = rep["legs"]["1"]["fleet"]
    assert fl["siblings"] == CLEAN and "SN-W" not in fl["sibling_serials"]
    f = fl["finding"]
    # the top fifth of the stroke (53..88 mm) holds the wear: its reversal beyond the leg's mean
    assert f["feature"].startswith("reversal 53..88") and f["sigma"] > 3 and f["value"] > 0.2
    assert "sibling legs of type HX-L300" in f["note"] and "FLEET (7 sibling legs" in text
    # the twin's spread: per target, per direction, across the siblings
    m = fl["map"]
    assert len(m["fleet_up_sd_um"]) == TARGETS.size and min(m["fleet_up_sd_um"]) > 0


def test_no_clean_leg_stands_out_from_its_siblings(fleet):
    _, paths, catalog, _ = fleet
    for serial in [f"SN-{i}" for i in range(CLEAN)]:
        session = read_session(paths[serial])
        twin = load_twin(f"fleet:{TYPE}", session=session, path=paths[serial], catalog=lambda: catalog.engine)
        assert serial not in twin.fleet[1].serials and twin.fleet[1].n == CLEAN
        comp = twin.comparison(1, error_map(session.points, 1), 5.0)
        assert comp["finding"] is None, comp["finding"]
        # a plain sigma above 3 alone is not a finding: with 7 siblings and 12 features a clean leg
        # gets one now and then (the plant's spread is uniform); the p over all features guards it
        assert not any(r["stands_out"] for r in comp["features"])
        assert all(r["p_value_all_features"] >= 0.0027 for r in comp["features"])


def test_fewer_than_three_siblings_is_refused_in_one_line(fleet, tmp_path, capsys):
    folder, paths, _, _ = fleet
    small = tmp_path / "small"
    small.mkdir()
    for serial in ("SN-0", "SN-1", "SN-2"):
        shutil.copy(paths[serial], small / paths[serial].name)
    # an older session of the leg under diagnosis: the same serial is never its own sibling
    _write(small / "leg0-older.h5", default_leg_configs(3, 1)[0], 99, "SN-0", 1)
    _, config = _index(small)
    code = main(["diagnose", str(small / paths["SN-0"].name), "--twin", f"fleet:{TYPE}", "--config", str(config)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert f"2 sibling leg(s) of type {TYPE}" in err[0] and "at least 3" in err[0]
    with pytest.raises(InputError, match="name the leg type"):
        load_twin("fleet:")


def test_a_sibling_without_material_temperature_makes_the_fleet_raw(fleet, tmp_path):
    _, paths, _, _ = fleet
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    for serial in ("SN-0", "SN-1", "SN-2", "SN-3"):
        shutil.copy(paths[serial], mixed / paths[serial].name)
    _write(mixed / "bare.h5", default_leg_configs(3, 8)[4], 4, "SN-X", 20, temperature=False)
    catalog, _ = _index(mixed)
    target = mixed / paths["SN-0"].name
    session = read_session(target)
    twin = load_twin(f"fleet:{TYPE}", session=session, path=target, catalog=lambda: catalog.engine)
    assert not twin.normalised and twin.info["basis"] == "raw" and "raw" in twin.description
    assert sorted(twin.fleet[1].serials) == ["SN-1", "SN-2", "SN-3", "SN-X"]
    from station.services.diagnosis_jobs import diagnose_session

    report, _ = diagnose_session(session, target, twin)
    assert "normalised_legs" not in report["twin"] and report["legs"]["1"]["fleet"]["basis"] == "raw"
