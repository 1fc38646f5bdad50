"""Replay end to end: sessions recorded on the simulated rig, replayed through the same Modbus and
serial clients, the sweep procedure and the recorder; analysis of the replay equals analysis of
the recording."""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from procedures.engine import events as ev
from procedures.engine.control import RunControl
from procedures.diagnosis import diagnose, to_json
from procedures.fit import fit, model_to_json
from procedures.reporting.iso230 import dumps as iso230_json, evaluate as iso230
from procedures.acquisition.plans import SweepPlan, iso230_plan
from procedures.io.recording.reader import read_session
from procedures.io.recording.schema import FLAG_REPLAYED, FLAG_RETRIED_BEAM, FLAG_RETRIED_DRIVE
from procedures.engine.runner import CallbackSink
from procedures.compensation.table import make_table, table_csv_text
from station.cli import main
from station.services.samples import FAULT_AFTER_INDEX, FAULT_LEG, FILES, open_sample_rig
from procedures.acquisition.replay_compare import compare_sessions
from station.commands.replay import parse_speed
from station.services.jobs import replay_sweep, retry_policy_of
from station.services.config import StationConfig
from station.services.jobs import run_sweep
from station.services.wiring import open_replay_rig
from tests.tooling import require_tool  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
RECORDINGS = REPO / "recordings"
CFG = StationConfig(operator="test")


def record(path: Path, plan: SweepPlan, inject=None, control: RunControl | None = None) -> None:
    """Record `plan` on the samples' simulated rig; `inject(rig, event)` may inject faults."""
    with open_sample_rig() as rig:
        sinks = [CallbackSink(lambda e: inject(rig, e))] if inject else []
        run_sweep(rig, plan, path, CFG, sinks=sinks, control=control)


def beam_and_drive_faults(rig, e) -> None:
    """One transient beam break on leg 1 (after point 5) and one drive fault on leg 2 (after 82,
    its 11th point: leg 2 starts at plan index 72)."""
    if isinstance(e, ev.PointMeasured):
        if e.record["index"] == 5:
            rig.sim.laser_server.set_beam_break(1, True)
        if e.record["index"] == 82:
            rig.sim.drive_server.inject_fault(2, "encoder")
    elif isinstance(e, ev.Fault) and e.kind == "beam_break":
        rig.sim.laser_server.set_beam_break(1, False)



def replay(original: Path, out: Path, speed=None):
    session = read_session(original)
    with open_replay_rig(original, speed, CFG) as rig:
        result = replay_sweep(rig, session, out, CFG)
        return result, rig.sim.mismatch, rig.sim.ended


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("live") / "live.h5"
    record(path, iso230_plan((1, 2), n_targets=9, cycles=4, irregular=False), inject=beam_and_drive_faults)
    return path


def schema_of(path: Path) -> dict:
    """What the schema checks look at: attribute names, row layouts, units, chunking."""
    with h5py.File(path, "r") as f:
        return {
            "root": sorted(f.attrs), "meta": sorted(f["meta"].attrs),
            "points": (f["points"].dtype, f["points"].chunks, f["points"].maxshape,
                       {k: v for k, v in f["points"].attrs.items()}),
            "faults": (f["faults"].dtype, f["faults"].chunks, {k: v for k, v in f["faults"].attrs.items()}),
        }


def test_replay_via_cli_gives_the_same_points_model_table_iso230_and_diagnosis(recorded, tmp_path, capsys):
    out = tmp_path / "replayed.h5"
    assert main(["replay", str(recorded), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "identical to the recording: 144 points (all fields), 2 faults, outcome completed" in printed
    live, rep = read_session(recorded), read_session(out)
    # the faults happened and were replayed at the same points, with the same retry flags
    assert sorted(live.faults["kind"].tolist()) == [b"beam_break", b"drive_fault"]
    assert np.count_nonzero(live.points["flags"] & (FLAG_RETRIED_BEAM | FLAG_RETRIED_DRIVE)) == 2
    assert compare_sessions(live, rep).identical
    for name in live.points.dtype.names:
        if name != "flags":
            assert live.points[name].tobytes() == rep.points[name].tobytes(), name
    assert np.all(rep.points["flags"] == live.points["flags"] | FLAG_REPLAYED)
    # same schema as a live session; marked as a replay; names the recording it replayed
    assert schema_of(out) == schema_of(recorded)
    assert rep.attrs["rig"] == "replay" and live.attrs["rig"] == "sim" and rep.outcome == "completed"
    assert rep.plan == live.plan
    # the identities (not the tables' states, nor the laser's air compensation record)
    identities = {k: v for k, v in rep.devices.items() if k == "interferometer" or (k.startswith("leg") and k[3:].isdigit())}
    assert identities and all(v.startswith("StationReplay") for v in identities.values())
    assert [v for k, v in rep.devices.items() if k.startswith("leg") and k.endswith("_compensation")] == ["bank 0 active, empty"] * 2
    assert f"R{live.sha256[:8]}" in rep.devices["interferometer"]
    # analysis: identical apart from the source hash/path and creation time
    src = dict(source_path="s.h5", source_sha256="0" * 64, created_utc="t")
    m_live, m_rep = fit(live.points), fit(rep.points)
    assert model_to_json(m_live, **src) == model_to_json(m_rep, **src)
    m_paper = model_to_json(fit(live.points, "paper"), **src)
    assert m_paper == model_to_json(fit(rep.points, "paper"), **src)
    assert table_csv_text(make_table(m_live)) == table_csv_text(make_table(m_rep))
    assert to_json(diagnose(live.points)) == to_json(diagnose(rep.points))
    assert iso230_json(iso230(live.points), {"path": "s.h5"}) == iso230_json(iso230(rep.points), {"path": "s.h5"})


def test_replayed_file_passes_the_schema_tools(recorded, tmp_path):
    out = tmp_path / "r.h5"
    result, mismatch, _ = replay(recorded, out)
    assert result.outcome == "completed" and mismatch is None
    h5dump = require_tool("h5dump")
    text = subprocess.run([h5dump, "-H", str(out)], capture_output=True, text=True, check=True).stdout
    assert 'DATASET "points"' in text and 'ATTRIBUTE "schema_version"' in text


def test_fault_cut_sample_reproduces_the_fault_at_the_same_point(tmp_path):
    original = RECORDINGS / FILES["fault"]
    out = tmp_path / "fault.replay.h5"
    result, mismatch, ended = replay(original, out)
    live, rep = read_session(original), read_session(out)
    assert result.outcome == "failed" == live.outcome and mismatch is None and not ended
    assert compare_sessions(live, rep).identical, compare_sessions(live, rep).differences
    last = rep.faults[-1]
    assert (int(last["index"]), int(last["leg"]), last["kind"], bool(last["gave_up"])) == (
        FAULT_AFTER_INDEX + 1, FAULT_LEG, b"beam_break", True)
    assert np.array_equal(rep.faults[["index", "run", "target_mm", "time_s", "attempt"]],
                          live.faults[["index", "run", "target_mm", "time_s", "attempt"]])
    assert len(rep.points) == FAULT_AFTER_INDEX + 1
    assert "beam_break at leg 2" in result.reason


def test_aborted_recording_replays_to_the_same_point_and_ends_aborted(tmp_path):
    original = tmp_path / "aborted.h5"
    control = RunControl()

    def abort_after_seven(rig, e):
        if isinstance(e, ev.PointMeasured) and e.done == 7:
            control.abort("operator went home")

    record(original, iso230_plan((1,), n_targets=6, cycles=2), inject=abort_after_seven, control=control)
    assert read_session(original).outcome == "aborted"
    result, mismatch, ended = replay(original, tmp_path / "r.h5")
    assert result.outcome == "aborted" and mismatch is None
    assert "ends here (its outcome was aborted; 7 points replayed)" in ended and ended in result.reason
    assert compare_sessions(read_session(original), read_session(tmp_path / "r.h5")).identical


def test_resumed_recording_replays_in_one_go_with_its_clock_restarting(tmp_path):
    original = tmp_path / "resumed.h5"
    plan = iso230_plan((1,), n_targets=6, cycles=2)
    control = RunControl()
    record(original, plan, inject=lambda rig, e: isinstance(e, ev.PointMeasured) and e.done == 9 and control.abort("break"),
           control=control)
    with open_sample_rig() as rig:  # a new rig, its clock starting at 0 again
        assert run_sweep(rig, plan, original, CFG, resume=True).outcome == "completed"
    live = read_session(original)
    assert len(live.resumed_utc) == 1 and np.any(np.diff(live.points["time_s"]) < 0)
    result, mismatch, ended = replay(original, tmp_path / "r.h5")
    assert result.outcome == "completed" and mismatch is None and not ended
    assert compare_sessions(live, read_session(tmp_path / "r.h5")).identical


def test_a_plan_asking_for_an_unrecorded_target_stops_naming_the_first_mismatch(recorded, tmp_path):
    plan = SweepPlan.from_dict(read_session(recorded).plan)
    targets = list(plan.targets_mm)
    targets[3] = targets[3] + 0.5
    other = SweepPlan("other", tuple(targets), plan.cycles, plan.legs)
    with open_replay_rig(recorded, None, CFG) as rig:
        result = run_sweep(rig, other, tmp_path / "o.h5", CFG)
        mismatch = rig.sim.mismatch
    assert result.outcome == "failed" and result.points == 3
    text = str(mismatch)
    assert f"replay: leg 1 run 1 target {targets[3]:.4f} mm (direction +1) was not recorded in {recorded}" in text
    assert f"{len(targets)} targets from {targets[0]:.4f} to" in text and "for leg 1" in text


def test_cli_reports_a_mismatch_in_one_line(recorded, tmp_path, capsys):
    tampered = tmp_path / "tampered.h5"
    shutil.copy(recorded, tampered)
    with h5py.File(tampered, "a") as f:
        plan = json.loads(f["meta"].attrs["plan"])
        plan["legs"] = [1, 2, 3]
        f["meta"].attrs["plan"] = json.dumps(plan)
    assert main(["replay", str(tampered), "--out", str(tmp_path / "t.h5")]) == 2
    err = capsys.readouterr().err  # the progress bar is on stderr too; the error is its last line
    last = err.strip().splitlines()[-1]
    assert last.startswith("station replay: error: replay: leg 3 was not recorded in") and "Traceback" not in err
    assert "(the recording has legs 1, 2)" in last


def test_cli_refuses_a_recording_with_an_unknown_reported_value(recorded, tmp_path, capsys):
    edited = tmp_path / "no-load.h5"
    shutil.copy(recorded, edited)
    with h5py.File(edited, "a") as f:
        row = f["points"][17]
        row["load_n"] = np.nan
        f["points"][17] = row
    assert main(["replay", str(edited), "--out", str(tmp_path / "n.h5")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"station replay: error: {edited}: point index 17 (leg 1 run 2 target") and "\n" not in err
    assert "has no recorded load_n (NaN)" in err and not (tmp_path / "n.h5").exists()


def test_cli_refuses_to_overwrite_and_checks_the_speed(recorded, tmp_path, capsys):
    assert main(["replay", str(recorded), "--out", str(recorded)]) == 2
    assert "is the recording being replayed" in capsys.readouterr().err
    assert parse_speed("max") is None and parse_speed("1") == 1.0 and parse_speed("10") == 10.0
    for bad in ("0", "-2", "fast", "nan"):
        with pytest.raises(argparse.ArgumentTypeError, match="speed factor"):
            parse_speed(bad)


def test_speed_ten_replays_ten_times_faster_than_recorded(tmp_path):
    original = tmp_path / "short.h5"
    plan = SweepPlan("short", (-0.6, 0.0, 0.6), cycles=1, legs=(1,), overrun_mm=0.2, dwell_s=0.5, averaging_s=0.0)
    record(original, plan)
    live = read_session(original)
    span_s = float(live.points["time_s"][-1])
    t0 = time.monotonic()
    result, mismatch, _ = replay(original, tmp_path / "r.h5", speed=10.0)
    wall = time.monotonic() - t0
    assert result.outcome == "completed" and mismatch is None
    assert span_s / 10 * 0.8 <= wall, (wall, span_s)
    assert compare_sessions(live, read_session(tmp_path / "r.h5")).identical


def test_retry_limits_follow_the_recording():
    live = read_session(RECORDINGS / FILES["fault"])
    policy = retry_policy_of(live)
    assert policy.beam_retries == int(live.faults["attempt"].max()) - 1 and policy.env_interval_s == -math.inf


# -- the sample recordings -------------------------------------------------------------------------

def test_sample_recordings_are_listed_small_and_readable():
    readme = (RECORDINGS / "README.md").read_text()
    for name in FILES.values():
        path = RECORDINGS / name
        assert path.stat().st_size < 5e6, f"{name} is {path.stat().st_size / 1e6:.1f} MB"
        assert name in readme
        s = read_session(path)
        assert s.attrs["rig"] == "sim" and len(s.points) > 0
    cal = read_session(RECORDINGS / FILES["calibration"])
    assert cal.outcome == "completed" and cal.legs == [1, 2, 3, 4, 5, 6]
    assert len(cal.points) == SweepPlan.from_dict(cal.plan).total_points
    assert set(cal.faults["kind"].tolist()) == {b"beam_break", b"drive_fault"}
    ver = read_session(RECORDINGS / FILES["verification"])
    assert ver.outcome == "completed" and ver.legs == [1, 2, 3, 4, 5, 6]
    # after compensation every leg's error range is smaller than in the calibration
    for leg in cal.legs:
        before = np.ptp(cal.points["error_um"][cal.points["leg"] == leg])
        after = np.ptp(ver.points["error_um"][ver.points["leg"] == leg])
        assert after < before, f"leg {leg}: {after:.2f} um after compensation, {before:.2f} um before"
    assert read_session(RECORDINGS / FILES["fault"]).outcome == "failed"


def test_fault_sample_regenerates_identically(tmp_path, capsys, caplog, monkeypatch):
    monkeypatch.setenv("STATION_CATALOG", "on")  # the samples are not indexed even so (no leg's record)
    monkeypatch.chdir(tmp_path)  # where a default catalog would land (runs/)
    assert main(["recordings", "--out", str(tmp_path), "--only", "fault"]) == 0
    import threading

    for t in threading.enumerate():  # a session is indexed in a thread of its own, after the run
        if t.name == "catalog-index":
            t.join(30)
    # made under a temporary name: indexing it named a file gone by then
    assert not [r.getMessage() for r in caplog.records if "catalog" in r.getMessage()]
    new, committed = read_session(tmp_path / FILES["fault"]), read_session(RECORDINGS / FILES["fault"])
    assert new.points.tobytes() == committed.points.tobytes()
    assert np.array_equal(new.faults[["index", "kind", "attempt", "time_s"]], committed.faults[["index", "kind", "attempt", "time_s"]])
    assert new.plan == committed.plan
    assert new.station_config["sim"]["jerk_mm_s3"] == 0.0  # the setting the samples were made with, recorded


def test_calibration_and_verification_samples_regenerate_identically(tmp_path, monkeypatch):
    """`station recordings` makes the calibration, then pushes the tables fitted to it and sweeps the
    compensated legs (the verification sample, confirmed as `station sweep --yes` would): every point
    of both equals the committed ones (the files' older dtypes read through the current schema)."""
    monkeypatch.chdir(tmp_path)
    assert main(["recordings", "--out", str(tmp_path), "--only", "calibration,verification"]) == 0
    for name in ("calibration", "verification"):
        new, committed = read_session(tmp_path / FILES[name]), read_session(RECORDINGS / FILES[name])
        assert len(new.points) == len(committed.points) > 0, name
        assert new.points.tobytes() == committed.points.tobytes(), name
        assert new.plan == committed.plan, name
    # the verification swept legs whose tables were active, and says so
    from procedures.io.recording.stage import active_tables

    assert sorted(active_tables(read_session(tmp_path / FILES["verification"]).devices)) == [1, 2, 3, 4, 5, 6]


def test_replay_reads_the_environment_again_only_where_the_recording_changed_it(recorded, tmp_path):
    """A replayed point whose recorded environment is the one of the point just before (same leg)
    keeps the values held instead of asking the instrument again; the session stays identical."""
    from drivers.interferometer import protocol as p
    from station.services.jobs import env_unchanged_at

    session = read_session(recorded)
    pts = np.sort(session.points, order="index")
    unchanged = env_unchanged_at(session.points)
    # the recorded rig reads its environment every 10 s of rig time, a point takes about 1 s
    assert 0 < len(unchanged) < len(pts)
    for i in unchanged:
        k = int(np.flatnonzero(pts["index"] == i)[0])
        assert pts["leg"][k] == pts["leg"][k - 1] and pts["material_temp_c"][k] == pts["material_temp_c"][k - 1]
    out = tmp_path / "env.h5"
    with open_replay_rig(recorded, None, CFG) as rig:
        result = replay_sweep(rig, session, out, CFG)
        asked = rig.sim.laser_server.commands[p.CMD_ENV]
    assert result.outcome == session.outcome
    assert asked <= len(pts) - len(unchanged) + len(session.faults)  # retried points may ask again
    assert compare_sessions(session, read_session(out)).identical
