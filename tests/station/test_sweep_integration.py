"""End-to-end sweeps on the simulated rig, through the real Modbus TCP and serial pty."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from drivers.plant.leg import systematic_error_um
from procedures.engine import events as ev
from procedures.engine.control import RunControl
from procedures.acquisition.plans import SweepPlan
from procedures.io.recording.reader import read_session
from procedures.engine.runner import CallbackSink, ListSink
from station.services.config import StationConfig
from station.services.jobs import run_sweep
from station.services.wiring import open_rig

REPO = Path(__file__).resolve().parents[2]
PLAN = SweepPlan("test", (-60.0, -23.0, 0.0, 17.0, 61.0), cycles=2, legs=(1, 3), dwell_s=1.0)


@pytest.fixture
def rig():
    with open_rig(StationConfig(), legs=(1, 2, 3, 4, 5, 6), time_scale=0.0) as r:
        yield r


def test_sweep_records_every_point_and_errors_follow_the_plant(rig, tmp_path):
    out = tmp_path / "s.h5"
    events = ListSink()
    result = run_sweep(rig, PLAN, out, StationConfig(), sinks=[events])
    assert result.outcome == "completed" and result.points == PLAN.total_points
    s = read_session(out)
    pts = s.points
    assert sorted(pts["index"]) == list(range(PLAN.total_points))
    assert s.outcome == "completed"
    # the measured error is the plant's error: systematic part within noise + pass scatter
    for leg in (1, 3):
        plant = rig.sim.plants[leg]
        lp = pts[pts["leg"] == leg]
        predicted = systematic_error_um(plant.cfg, lp["target_mm"], lp["direction"], lp["material_temp_c"],
                                        lp["load_n"], lp["time_s"])
        resid = lp["error_um"] - predicted
        resid -= resid.mean()  # the zero at mid-stroke removes a constant
        assert np.abs(resid).max() < 0.4, f"leg {leg}: max deviation {np.abs(resid).max():.3f} um"
        # the drive's own position follows the target (table inactive) within a micrometre
        assert np.allclose(lp["drive_position_mm"], lp["target_mm"], atol=1e-3)
    # every point went through the interferometer and carries the environment
    assert np.all(np.isfinite(pts["air_temp_c"])) and np.all(pts["signal_pct"] > 0)
    for leg in (1, 3):
        assert not rig.axes[leg].status().enabled, "drives are left disabled after a sweep"


def test_abort_mid_sweep_stops_drives_and_leaves_a_valid_file(rig, tmp_path):
    out = tmp_path / "a.h5"
    control = RunControl()
    seen = []

    def on_event(e):
        if isinstance(e, ev.PointMeasured):
            seen.append(e.record["index"])
            if len(seen) == 7:
                control.abort("test abort")

    result = run_sweep(rig, PLAN, out, StationConfig(), sinks=[CallbackSink(on_event)], control=control)
    assert result.outcome == "aborted"
    s = read_session(out)
    assert list(s.points["index"]) == seen[: len(s.points)] and len(s.points) == 7
    assert s.outcome == "aborted"
    for leg in PLAN.legs:
        st = rig.axes[leg].status()
        assert not st.moving and not st.enabled


def test_beam_break_is_retried_then_recorded_with_its_point(rig, tmp_path):
    out = tmp_path / "b.h5"
    laser = rig.sim.laser_server
    state = {"n": 0}

    def on_event(e):
        if isinstance(e, ev.PointMeasured):
            state["n"] += 1
            if state["n"] == 3:
                laser.set_beam_break(1, True)
        if isinstance(e, ev.Fault) and e.attempt == 2:
            laser.set_beam_break(1, False)  # the technician clears the beam path

    events = ListSink()
    result = run_sweep(rig, PLAN, out, StationConfig(), sinks=[events, CallbackSink(on_event)])
    assert result.outcome == "completed"
    faults = events.of(ev.Fault)
    assert [f.kind for f in faults] == ["beam_break", "beam_break"] and not any(f.gave_up for f in faults)
    s = read_session(out)
    assert len(s.faults) == 2 and int(s.faults["index"][0]) == faults[0].index
    hit = s.points[s.points["index"] == faults[0].index]
    assert hit["flags"][0] & 1, "the retried point carries the beam-retry flag"


def test_persistent_beam_break_fails_the_sweep_resumably(rig, tmp_path):
    out = tmp_path / "f.h5"
    laser = rig.sim.laser_server
    state = {"n": 0}

    def on_event(e):
        if isinstance(e, ev.PointMeasured):
            state["n"] += 1
            if state["n"] == 4:
                laser.set_beam_break(1, True)

    result = run_sweep(rig, PLAN, out, StationConfig(), sinks=[CallbackSink(on_event)])
    assert result.outcome == "failed" and "beam_break" in result.reason
    s = read_session(out)
    assert len(s.points) == 4 and s.outcome == "failed"
    assert s.faults["gave_up"][-1] == 1 and int(s.faults["index"][-1]) == 4
    laser.set_beam_break(1, False)
    result = run_sweep(rig, PLAN, out, StationConfig(), resume=True)
    assert result.outcome == "completed"
    idx = read_session(out).points["index"]
    assert sorted(idx) == list(range(PLAN.total_points)) and len(set(idx)) == len(idx)


def test_drive_fault_mid_sweep_is_reset_and_retried(rig, tmp_path):
    out = tmp_path / "d.h5"
    state = {"n": 0}

    def on_event(e):
        if isinstance(e, ev.PointMeasured):
            state["n"] += 1
            if state["n"] == 5:
                rig.sim.drive_server.inject_fault(1, 0x5530)

    events = ListSink()
    result = run_sweep(rig, PLAN, out, StationConfig(), sinks=[events, CallbackSink(on_event)])
    assert result.outcome == "completed"
    faults = events.of(ev.Fault)
    assert faults and faults[0].kind == "drive_fault" and not faults[-1].gave_up


CHILD = r"""
import sys
import time
from procedures.engine import events as ev
from procedures.acquisition.plans import SweepPlan
from procedures.engine.runner import CallbackSink
from station.services.config import StationConfig
from station.services.jobs import run_sweep
from station.services.wiring import open_rig

plan = SweepPlan("kill", tuple(float(x) for x in range(-80, 81, 10)), cycles=3, legs=(1, 2), dwell_s=1.0)
HOLD_AT = int(sys.argv[3])
def report(e):
    if isinstance(e, ev.PointMeasured):
        print(e.record["index"], flush=True)   # after the recorder sink: on disk
        if e.record["index"] >= HOLD_AT:  # the parent is late to kill: wait for it, do not finish
            time.sleep(3600)
with open_rig(StationConfig(), legs=plan.legs, time_scale=float(sys.argv[2])) as rig:
    run_sweep(rig, plan, sys.argv[1], StationConfig(), sinks=[CallbackSink(report)])
"""


def test_sigkill_mid_sweep_then_resume_gives_every_point_once(tmp_path):
    out = tmp_path / "k.h5"
    kill_after = random.Random().randint(5, 150)
    # the kill lands wherever the sweep is while the parent reacts (a point being measured, written,
    # flushed); the child goes on for up to 40 points more, then waits, so a loaded machine's late
    # reaction cannot let it finish
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(out), "0.0005", str(kill_after + 40)], stdout=subprocess.PIPE,
                            text=True, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)})
    reported = []
    for line in proc.stdout:
        reported.append(int(line))
        if len(reported) >= kill_after:
            os.kill(proc.pid, signal.SIGKILL)
            break
    proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL, "the sweep ended before the kill"
    s = read_session(out)
    recorded = set(int(i) for i in s.points["index"])
    assert set(reported) <= recorded, f"reported but lost: {sorted(set(reported) - recorded)}"
    r = subprocess.run([sys.executable, "-m", "station.cli", "sweep", "--sim", "--resume", str(out)],
                       cwd=REPO, capture_output=True, text=True, timeout=120,
                       env={**os.environ, "PYTHONPATH": str(REPO)})
    assert r.returncode == 0, r.stderr + r.stdout
    idx = [int(i) for i in read_session(out).points["index"]]
    total = 17 * 2 * 3 * 2
    assert sorted(idx) == list(range(total)), "no missing and no duplicate point after resume"


def test_ctrl_c_on_the_command_line_stops_and_leaves_a_resumable_file(tmp_path):
    out = tmp_path / "c.h5"
    proc = subprocess.Popen(
        [sys.executable, "-m", "station.cli", "sweep", "--sim", "--legs", "1", "--cycles", "3", "--n-targets", "15",
         "--time-scale", "0.002", "--out", str(out)],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)})
    # wait until the file holds a few points, then press Ctrl-C
    import time
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if out.exists():
            try:
                if len(read_session(out).points) >= 5:
                    break
            except Exception:
                pass
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr  # Ctrl-C ends every command with 130
    assert "Traceback" not in stderr and "resume with: station sweep --resume" in stdout
    s = read_session(out)
    assert s.outcome == "aborted" and 5 <= len(s.points) < 90
    r = subprocess.run([sys.executable, "-m", "station.cli", "sweep", "--sim", "--resume", str(out)],
                       cwd=REPO, capture_output=True, text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert r.returncode == 0, r.stderr
    assert sorted(read_session(out).points["index"]) == list(range(90))


def test_a_sweep_with_a_table_active_warns_and_records_the_table_state(rig, tmp_path):
    from drivers.interfaces import TableBank

    axis = rig.axes[1]
    bank = 1 - axis.active_bank()
    axis.write_table(bank, TableBank(-90.0, 18.0, tuple([0.5] * 11), tuple([1.5] * 11)))
    axis.activate_table(bank)
    events = ListSink()
    cfg = StationConfig()
    cfg.metrology.calibration_due = "2999-01-01"  # a laser in calibration: the table's is the only warning
    asked = []
    # a calibration sweep of a compensated leg is asked first (services.jobs.check_compensation)
    result = run_sweep(rig, PLAN, tmp_path / "t.h5", cfg, sinks=[events],
                       confirm_compensated=lambda question: asked.append(question) or True)
    assert result.outcome == "completed"
    assert len(asked) == 1 and asked[0].startswith("A compensation table is active (leg 1: bank")
    warnings = [m for m in events.of(ev.Message) if m.level == "warning"]
    assert len(warnings) == 1 and warnings[0].text.startswith("leg 1: a compensation table is active")
    devices = read_session(tmp_path / "t.h5").devices
    assert devices["leg1_compensation"].startswith(f"bank {bank} active, 11 points from -90.000 mm every 18 mm")
    assert "empty" in devices["leg3_compensation"]
    assert read_session(tmp_path / "t.h5").attrs["stage"] == "other"  # not an as-found calibration


def test_fit_warns_when_the_recording_was_made_with_a_table_active(rig, tmp_path, capsys):
    from drivers.interfaces import TableBank
    from station.cli import main

    axis = rig.axes[3]
    bank = 1 - axis.active_bank()
    axis.write_table(bank, TableBank(-90.0, 18.0, tuple([0.5] * 11), tuple([1.5] * 11)))
    axis.activate_table(bank)
    plan = SweepPlan("test", tuple(float(x) for x in np.linspace(-60, 60, 9)), cycles=3, legs=(1, 3))
    assert run_sweep(rig, plan, tmp_path / "w.h5", StationConfig(),
                     confirm_compensated=lambda question: True).outcome == "completed"
    assert main(["fit", str(tmp_path / "w.h5"), "--out", str(tmp_path / "m.json")]) == 0
    out = capsys.readouterr().out
    assert "warning: leg 3 was recorded with a compensation table active" in out
    assert "warning: leg 1" not in out
