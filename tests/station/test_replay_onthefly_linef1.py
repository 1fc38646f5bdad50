"""Replay of on-the-fly sessions recorded with the µLine-F1 (issue 34, parts 2 and 3): a session
recorded on the simulated rig (real Modbus TCP on 127.0.0.1, the laser's frames on a real pty,
real HDF5) is replayed by `station replay` through the replay devices (the replay drive's Modbus
server, the replay instrument's pty) and must give the recorded points back, every field bit for
bit (tolerance 0: the replay instrument sends every number with `repr`, the drive's values come
back through the registers they were recorded through). A pass's readings there carry no signal
level (NaN, from the stream's alignment): the replay keeps them NaN. A pass retried after a fault
of the laser (a gap in the stream, a beam break, line noise) replays failing the same way, at the
recorded time; one retried after a drive fault cannot be replayed faithfully and is refused up
front in one line, nothing written."""

from __future__ import annotations

import logging
import os

import numpy as np
import pytest

from procedures.acquisition.plans import onthefly_plan
from procedures.engine import events as ev
from procedures.engine.control import RunControl
from procedures.engine.runner import CallbackSink
from procedures.io.recording.reader import read_session
from procedures.io.recording.schema import FLAG_ANCHOR, FLAG_REPLAYED
from procedures.vocabulary import InputError
from station.cli import main
from tests.tooling import onthefly_config
from station.services.jobs import run_sweep
from station.services.replay_job import ReplayRequest, prepare_replay
from station.services.wiring import open_rig

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
os.environ.setdefault("STATION_CATALOG", "off")

# nine targets over +/-20 mm, one cycle per speed (10 and 20 mm/s): 40 points, about 21 s of rig time
PLAN = onthefly_plan((1,), cycles=2, step_mm=5.0, min_mm=-20.0, max_mm=20.0, dwell_s=0.2, averaging_s=0.2)



def _record(tmp_path, protocol: str, name: str, sinks=()):
    cfg = onthefly_config(tmp_path, protocol)
    out = tmp_path / name
    with open_rig(cfg, legs=(1,), time_scale=0.0) as rig:
        result = run_sweep(rig, PLAN, out, cfg, sinks=list(sinks), index=False)
        assert not rig.sim.laser_server.failures
    return result, read_session(out)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The µLine-F1's on-the-fly session of leg 1, and the station laser's of the same plan."""
    tmp = tmp_path_factory.mktemp("otf-replay")
    return {protocol: _record(tmp, protocol, f"otf-{protocol}.h5")[1] for protocol in ("linef1", "station")}


def _replay(session, out, capsys):
    rc = main(["replay", str(session.path), "--out", str(out)])
    text = capsys.readouterr()
    return rc, text.out, text.err


@pytest.mark.timeout(60)
@pytest.mark.parametrize("protocol", ["linef1", "station"])
def test_an_onthefly_session_replays_to_the_recorded_points(recorded, protocol, tmp_path, capsys):
    session = recorded[protocol]
    pts = session.points
    moving = (pts["flags"] & FLAG_ANCHOR) == 0
    assert session.outcome == "completed" and len(pts) == 40 and moving.sum() == 36
    assert np.all(np.isfinite(pts["speed_mm_s"][moving]))
    if protocol == "linef1":  # the stream's alignment gives no signal level at a target
        assert np.all(np.isnan(pts["signal_pct"][moving])) and np.all(np.isfinite(pts["signal_pct"][~moving]))
    out = tmp_path / "replayed.h5"
    rc, stdout, err = _replay(session, out, capsys)
    assert rc == 0, err
    assert "identical to the recording: 40 points (all fields)" in stdout
    # the engineer is told how a µLine-F1 session is replayed (not through its frames)
    assert ("recorded with the µLine-F1: its recorded readings are served by the replay instrument over the "
            "station's protocol, each pass's at the replay drive's compare pulses" in stdout) == (protocol == "linef1")
    replayed = read_session(out)
    assert replayed.attrs["rig"] == "replay"
    a = np.sort(pts, order="index")
    b = np.sort(replayed.points, order="index")
    assert np.array_equal(a["index"], b["index"])
    assert np.all(b["flags"] & FLAG_REPLAYED)
    for name in a.dtype.names:  # point for point, every field, bit for bit (NaN stays NaN)
        if name == "flags":
            assert np.array_equal(a[name] | FLAG_REPLAYED, b[name])
        elif a.dtype[name].kind == "f":
            assert np.array_equal(a[name], b[name], equal_nan=True), name
        else:
            assert np.array_equal(a[name], b[name]), name
    assert float(np.max(np.abs(a["error_um"] - b["error_um"]))) == 0.0
    # the station applied the index on the µLine-F1's session: its replay says so too
    assert replayed.devices["laser_air_compensation"] == session.devices["laser_air_compensation"]


def _record_with(tmp_path, protocol: str, name: str, fault):
    """A session of PLAN with `fault(rig)` called once the first pass's anchor (index 9) is
    recorded, so it hits the second pass; a beam broken on the station's laser is restored at
    the fault it causes (the pass is retried)."""
    state = {}

    def on_event(e):
        if isinstance(e, ev.PointMeasured) and int(e.record["index"]) == 9:
            fault(state["rig"])
        elif isinstance(e, ev.Fault) and protocol == "station":
            state["rig"].sim.laser_server.set_beam_break(1, False)

    cfg = onthefly_config(tmp_path, protocol)
    out = tmp_path / name
    with open_rig(cfg, legs=(1,), time_scale=0.0) as rig:
        state["rig"] = rig
        result = run_sweep(rig, PLAN, out, cfg, sinks=[CallbackSink(on_event)], index=False)
    session = read_session(out)
    assert result.outcome == "completed" and len(session.points) == 40
    assert len(session.faults) >= 1 and {int(f["run"]) for f in session.faults} == {2}
    return session


RETRIED = {  # case -> (protocol, the fault put into the second pass, the kind recorded)
    "linef1-gap-1s": ("linef1", lambda rig: rig.sim.laser_server.inject("gap", duration_s=1.0), "error"),  # cannot align
    "linef1-gap-3s": ("linef1", lambda rig: rig.sim.laser_server.inject("gap", duration_s=3.0), "timeout"),  # too few frames
    "station-beam": ("station", lambda rig: rig.sim.laser_server.set_beam_break(1, True), "beam_break"),
    "station-noise": ("station", lambda rig: rig.sim.laser_server.inject_garbage(3), "framing"),  # a command's 3 tries
}


@pytest.mark.timeout(60)
@pytest.mark.parametrize("case", sorted(RETRIED))
def test_a_pass_retried_after_a_fault_of_the_laser_replays_with_its_fault(case, tmp_path, capsys):
    protocol, fault, kind = RETRIED[case]
    session = _record_with(tmp_path, protocol, "retried.h5", fault)
    assert [(_s(f["kind"]), int(f["attempt"]), int(f["gave_up"])) for f in session.faults] == [(kind, 1, 0)]
    out = tmp_path / "retried.replay.h5"
    rc, stdout, err = _replay(session, out, capsys)
    assert rc == 0, err
    assert "identical to the recording: 40 points (all fields), 1 faults" in stdout
    replayed = read_session(out)
    a, b = session.faults[0], replayed.faults[0]
    for key in ("index", "leg", "run", "target_mm", "time_s", "kind", "attempt", "gave_up"):
        assert a[key] == b[key], key  # the fault's time bit for bit: the replay fails the attempt at it
    assert np.array_equal(np.sort(session.points, order="index")["measured_mm"],
                          np.sort(replayed.points, order="index")["measured_mm"])


def _s(value) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


@pytest.mark.timeout(60)
def test_an_onthefly_session_with_a_drive_fault_in_a_pass_is_refused_up_front_in_one_line(tmp_path, capsys):
    """A drive fault inside the second pass: the pass is retried; a replay cannot make the moving
    pass fail with it again, so the replay is refused before anything is opened or written."""
    session = _record_with(tmp_path, "linef1", "drive.h5",
                           lambda rig: rig.sim.drive_server.inject_fault(1, "overcurrent"))
    assert {_s(f["kind"]) for f in session.faults} == {"drive_fault"}
    replayed = tmp_path / "drive.replay.h5"
    with pytest.raises(InputError, match="on-the-fly pass 2 met a drive fault"):
        prepare_replay(ReplayRequest(session.path, replayed))
    rc, stdout, err = _replay(session, replayed, capsys)
    assert rc == 2 and not replayed.exists() and "sweep" not in stdout
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    assert "leg 1 on-the-fly pass 2 met a drive fault (attempt 1) and was retried" in lines[0]
    assert "station fit" in lines[0]  # what to do instead


@pytest.mark.timeout(60)
@pytest.mark.parametrize("protocol", ["linef1", "station"])
def test_an_onthefly_session_cut_short_replays_to_where_it_ends_and_is_aborted_there(protocol, tmp_path, capsys):
    """Aborted by the operator once the second pass is recorded: the replay runs the third pass's
    first attempt, finds the recording ends there, and aborts the run (it replayed into a
    mismatch, with beam breaks the recording does not have, and failed)."""
    control = RunControl()

    def stop_after_pass_2(e):
        if isinstance(e, ev.PointMeasured) and int(e.record["index"]) == 12:
            control.abort("operator")

    cfg = onthefly_config(tmp_path, protocol)
    out = tmp_path / "cut.h5"
    with open_rig(cfg, legs=(1,), time_scale=0.0) as rig:
        result = run_sweep(rig, PLAN, out, cfg, sinks=[CallbackSink(stop_after_pass_2)], control=control, index=False)
    session = read_session(out)
    assert result.outcome == "aborted" and len(session.points) == 20 and len(session.faults) == 0
    replayed_path = tmp_path / "cut.replay.h5"
    rc, stdout, err = _replay(session, replayed_path, capsys)
    assert rc == 0, err
    assert "(aborted, 20 points; rig replay)" in stdout and "identical to the recording" in stdout
    replayed = read_session(replayed_path)
    assert replayed.outcome == "aborted" and len(replayed.faults) == 0
    assert np.array_equal(np.sort(session.points, order="index")["measured_mm"],
                          np.sort(replayed.points, order="index")["measured_mm"])
