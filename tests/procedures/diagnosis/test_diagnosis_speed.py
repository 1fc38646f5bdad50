"""On-the-fly data from other software (issue 25 item 7): `speed_mm_s` in the interchange CSV and in
import maps, and the speed-dependent error diagnosed from it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from drivers.plant.leg import default_leg_configs
from procedures.io.csv_io import import_csv
from procedures.diagnosis import diagnose
from procedures.vocabulary import InputError
from procedures.io.import_map import convert, load_map
from procedures.io.recording.reader import read_session
from procedures.synthetic import synth_session


def on_the_fly(speeds=(5.0, 10.0, 20.0)):
    """A leg read while moving, each cycle at another speed: the plant's dynamic error (the leg
    end lags the encoder by dynamic_lag_*_s x speed) on top of its static error."""
    cfg = replace(default_leg_configs(3, 1)[0], enabled=frozenset({"lead", "longwave", "wobble", "noise", "run_offset",
                                                                   "backlash"}))
    pts = synth_session({1: cfg}, np.linspace(-90, 90, 91), 6, seed=5, dwell_s=0.5)
    v = np.array([speeds[(r - 1) // 2 % len(speeds)] for r in pts["run"]]) * pts["direction"]
    pts["speed_mm_s"] = v
    pts["error_um"] += -np.where(v > 0, cfg.dynamic_lag_up_s, cfg.dynamic_lag_down_s) * v * 1000.0
    return pts, cfg


def _csv(pts, path):
    lines = ["leg,run,direction,target_mm,error_um,time_s,speed_mm_s"]
    floats = ("target_mm", "error_um", "time_s", "speed_mm_s")
    lines += [f"{p['leg']},{p['run']},{p['direction']:+d}," + ",".join(repr(float(p[k])) for k in floats) for p in pts]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_speed_in_the_interchange_csv_makes_the_lag_diagnosable(tmp_path):
    pts, cfg = on_the_fly()
    import_csv(_csv(pts, tmp_path / "otf.csv"), tmp_path / "otf.h5")
    got = read_session(tmp_path / "otf.h5").points
    assert np.allclose(np.sort(got["speed_mm_s"]), np.sort(pts["speed_mm_s"]))
    found = {f["effect"]: f["parameters"] for f in diagnose(got)["findings"]}
    assert set(found) == {"speed", "backlash"}
    assert found["speed"]["lag_up_ms"] == pytest.approx(1e3 * cfg.dynamic_lag_up_s, rel=0.05)
    assert found["speed"]["lag_down_ms"] == pytest.approx(1e3 * cfg.dynamic_lag_down_s, rel=0.05)


def test_one_speed_per_direction_cannot_be_told_from_a_reversal_and_says_so():
    pts, _ = on_the_fly(speeds=(10.0,))
    leg = diagnose(pts)["legs"]["1"]
    cand = {c["effect"]: c for c in leg["candidates"]}["speed"]
    assert cand["status"] == "not applicable" and "reversal" in cand["reason"]


def test_a_speed_out_of_range_is_refused_naming_line_and_field(tmp_path):
    src = tmp_path / "bad.csv"
    src.write_text("leg,run,direction,target_mm,error_um,speed_mm_s\n1,1,1,0,1.0,10\n1,1,1,1,1.0,5000\n")
    with pytest.raises(InputError, match=r"line 3.*speed_mm_s.*5000 mm/s"):
        import_csv(src, tmp_path / "bad.h5")
    assert not (tmp_path / "bad.h5").exists()


def test_an_import_map_can_name_the_speed_column(tmp_path):
    m = tmp_path / "m.toml"
    m.write_text('[columns]\ntarget = "T"\nerror = "E"\nspeed_mm_s = "V"\n[defaults]\nleg = 2\n')
    data = tmp_path / "d.csv"
    data.write_text("T,E,V\n0,1.5,12.5\n1,1.25,12.5\n")
    conv = convert(data, load_map(m))
    header, row = conv.csv_text.splitlines()[:2]
    assert header.split(",")[-1] == "speed_mm_s" and float(row.split(",")[-1]) == 12.5
