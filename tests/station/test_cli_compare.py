"""`station compare`: sessions of one reference leg from several stations. A 1.5 um station bias
is flagged; without it |E_n| <= 1 on at least 95 % of the targets. Synthetic sessions (the plant,
straight) for three stations, and the real simulated rig (Modbus on loopback, a pty laser) with
the bias put on through the documented [sim] laser_offset_um."""

from __future__ import annotations

import json

import numpy as np
import pytest

from drivers.plant.leg import default_leg_configs
from station.cli import main
from station.services.config import StationConfig
from procedures.synthetic import synth_session
from tests.tooling import write_identified_session

BIAS_UM = 1.5


def _synth(path, seed: int, bias_um: float, station: str, serial: str = "REF-1", started_utc: str | None = None):
    points = synth_session({1: default_leg_configs(0)[0]}, np.linspace(-90.0, 90.0, 11), cycles=5, seed=seed)
    points["error_um"] += bias_um  # the station's laser reads long by bias_um everywhere
    return write_identified_session(path, points, station_id=station, serial=serial, started_utc=started_utc)


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    d = tmp_path_factory.mktemp("cmp")
    return {name: _synth(d / f"{name}.h5", seed, bias, name.upper())
            for name, seed, bias in (("a", 1, 0.0), ("b", 2, BIAS_UM), ("c", 3, 0.0))}


def _result(tmp_path, capsys, *paths, rc: int):
    out = tmp_path / "out"
    tmp_path.mkdir(exist_ok=True)  # --out's parent must exist (a folder output's parents are never made)
    assert main(["compare", *map(str, paths), "--out", str(out)]) == rc
    printed = capsys.readouterr().out
    assert {p.name for p in out.iterdir()} == {"compare.json", "compare.md", "compare.png"}
    return json.loads((out / "compare.json").read_text()), printed


def test_three_stations_flag_the_biased_one_only(synthetic, tmp_path, capsys):
    c, printed = _result(tmp_path, capsys, synthetic["a"], synthetic["b"], synthetic["c"], rc=1)
    flagged = {s["station_id"]: s["flagged"] for s in c["stations"]}
    assert flagged == {"A": False, "B": True, "C": False}
    pairs = {(p["a"][0], p["b"][0]): p for p in c["pairs"]}
    assert pairs["A", "C"]["share_within_pct"] >= 95.0 and not pairs["A", "C"]["disagree"]
    for key in (("A", "B"), ("B", "C")):
        p = pairs[key]
        assert p["disagree"] and p["exceed"] >= p["critical_count"]
        sign = -1 if key[0] == "A" else 1  # A - B is negative, B - C positive
        for d in ("up", "down"):
            assert sign * p["mean_difference_um"][d] == pytest.approx(BIAS_UM, abs=0.3)
    assert "B (b.h5): FLAGGED (disagrees with A (a.h5), C (c.h5))" in printed


def test_binomial_rule():
    from procedures.reporting.compare import binomial_tail, critical_count

    # 22 targets at 5 %: P(X >= 4) = 0.0239 <= 5 %, P(X >= 3) = 0.0952 > 5 %
    assert critical_count(22) == 4
    assert binomial_tail(3, 22, 0.05) > 0.05 >= binomial_tail(4, 22, 0.05)
    assert binomial_tail(0, 10, 0.3) == pytest.approx(1.0)


def test_another_leg_is_refused_naming_both(synthetic, tmp_path, capsys):
    other = _synth(tmp_path / "other.h5", 4, 0.0, "D", serial="REF-2")
    assert main(["compare", str(synthetic["a"]), str(other), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "a.h5 measured leg REF-1 but" in err and "other.h5 measured leg REF-2" in err
    assert not (tmp_path / "o").exists()


def _rig_session(path, station: str, noise_seed: int, offset_um: float):
    """A sweep of leg 1 (serial REF-1) on the simulated rig: the same plant (seed 0), its own
    measurement noise, the station's laser offset."""
    from procedures.acquisition.plans import iso230_plan
    from station.services.jobs import run_sweep
    from station.services.wiring import open_rig

    cfg = StationConfig(operator="test", id=station)
    cfg.sim.laser_offset_um = offset_um
    cfg.leg_identity = {1: {"serial": "REF-1", "leg_type": "HX300"}}
    plan = iso230_plan((1,), -90.0, 90.0, step_mm=18.0, cycles=5)
    with open_rig(cfg, legs=(1,), time_scale=0.0, noise_seed=noise_seed) as rig:
        assert run_sweep(rig, plan, path, cfg).outcome == "completed"
    return path


def test_real_simulated_rig_bias_flagged_and_agreement_without(tmp_path, capsys):
    a = _rig_session(tmp_path / "a.h5", "A", 11, 0.0)
    b = _rig_session(tmp_path / "b.h5", "B", 12, BIAS_UM)
    c = _rig_session(tmp_path / "c.h5", "C", 13, 0.0)
    unbiased, _ = _result(tmp_path / "ac", capsys, a, c, rc=0)
    biased, _ = _result(tmp_path / "ab", capsys, a, b, rc=1)
    (pair,) = unbiased["pairs"]
    print(f"no bias: |E_n| <= 1 at {pair['share_within_pct']:.1f} % of {pair['n_targets']} targets, max |E_n| "
          f"{max(abs(r['E_n']) for r in pair['rows']):.2f}")
    assert pair["share_within_pct"] >= 95.0 and not any(s["flagged"] for s in unbiased["stations"])
    (pair,) = biased["pairs"]
    print(f"1.5 um bias: |E_n| > 1 at {pair['exceed']} of {pair['n_targets']} targets, mean A - B "
          f"{pair['mean_difference_um']}, min |E_n| {min(abs(r['E_n']) for r in pair['rows']):.2f}")
    assert all(s["flagged"] for s in biased["stations"])
    assert pair["mean_difference_um"]["up"] == pytest.approx(-BIAS_UM, abs=0.3)


def test_two_sessions_of_one_station_are_called_a_repeat(synthetic, tmp_path, capsys):
    again = _synth(tmp_path / "a2.h5", 5, 0.0, "A")
    c, printed = _result(tmp_path, capsys, synthetic["a"], again, rc=0)
    assert "a.h5 and a2.h5 are both from station A: a repeat on one station" in c["note"] and "repeat" in printed


def test_sessions_beyond_the_comparison_window_are_refused(tmp_path, capsys):
    """The window of the web's /compare ([catalog] compare_window_days) bounds `station compare`
    too: 100 days apart is refused by default (90) in one line naming both, compared with 120."""
    a = _synth(tmp_path / "early.h5", 1, 0.0, "A", started_utc="2026-01-01T08:00:00Z")
    b = _synth(tmp_path / "late.h5", 2, 0.0, "B", started_utc="2026-04-11T08:00:00Z")
    assert main(["compare", str(a), str(b), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "early.h5 and late.h5 were measured 100 days apart" in err[0]
    assert "comparison window of 90 days" in err[0] and not (tmp_path / "o").exists()
    wide = tmp_path / "wide.toml"
    wide.write_text("[catalog]\ncompare_window_days = 120\n")
    assert main(["compare", str(a), str(b), "--out", str(tmp_path / "o"), "--config", str(wide)]) == 0
    assert json.loads((tmp_path / "o" / "compare.json").read_text())["pairs"][0]["n_targets"] == 22
