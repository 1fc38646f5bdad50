"""The rig session without any front end (station.services.rig_session): connection, rig actions,
the soft-limit-checked move and the lock discipline, on the simulated rig (real Modbus TCP and
serial pty, time scale 0); and the session names (station.services.sessions)."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from procedures.vocabulary import InputError
from station.services.config import StationConfig
from station.services.sweep_job import OutputExists, SweepRequest, prepare_sweep
from station.services.rig_session import (
    ActionRefused,
    MoveRequest,
    RigBusy,
    RigSession,
    checked_move,
    holding_rig,
    rig_action,
)
from station.services.sessions import default_session_path, new_session_problem, replay_output_path

pytestmark = pytest.mark.timeout(120)


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    cfg = StationConfig()
    cfg.recordings_dir = str(tmp_path_factory.mktemp("runs"))
    s = RigSession(cfg, (1, 2), time_scale=0.0)
    old, attempt = s.detach()
    assert s.state == "connecting" and old is None
    assert s.accept(s.open_rig_for(old, s.lock), attempt)
    assert s.state == "connected" and sorted(s.rig.axes) == [1, 2]
    yield s
    s.close()
    assert s.rig is None


def test_a_superseded_connect_is_not_kept(session):
    s = RigSession(session.cfg, (1,))
    _, first = s.detach()
    _, second = s.detach()
    assert not s.accept(object(), first) and s.rig is None  # the caller closes it
    assert not s.fail("late", first) and s.error == ""
    assert s.fail("cannot connect", second) and (s.state, s.error) == ("not connected", "cannot connect")


def test_enable_move_and_refusals(session):
    rig, lock = session.rig, session.lock
    rig_action(rig, lock, "reset", (1,))
    rig_action(rig, lock, "disable", (1,))
    with pytest.raises(ActionRefused, match="not enabled: enable it"):
        checked_move(rig, lock, 1, MoveRequest(target_mm=1.0))
    rig_action(rig, lock, "enable", (1,))
    lim = rig.axes[1].limits()
    position, speed = checked_move(rig, lock, 1, MoveRequest(target_mm=1.5))
    assert abs(position - 1.5) < 1e-3 and speed == pytest.approx(0.25 * lim.max_velocity_mm_s)  # JOG_SPEED_FRACTION
    position, speed = checked_move(rig, lock, 1, MoveRequest(step_mm=-0.5, speed_mm_s=1e9))
    assert abs(position - 1.0) < 1e-3 and speed == lim.max_velocity_mm_s  # limited to the drive's maximum
    before = rig.axes[1].status().position_mm
    with pytest.raises(ActionRefused, match="beyond the drive's soft limits.*nothing moved"):
        checked_move(rig, lock, 1, MoveRequest(target_mm=lim.max_mm + 1.0))
    with pytest.raises(ActionRefused, match="not a speed > 0"):
        checked_move(rig, lock, 1, MoveRequest(target_mm=0.0, speed_mm_s=0.0))
    assert rig.axes[1].status().position_mm == pytest.approx(before, abs=1e-4)
    rig_action(rig, lock, "home", (1,))
    assert abs(rig.axes[1].status().position_mm) < 1e-3


def test_a_stop_never_waits_for_the_lock_and_the_rest_are_refused_as_busy(session):
    rig, lock = session.rig, session.lock
    rig_action(rig, lock, "enable", (1, 2))
    with holding_rig(lock, 1.0, "held"):  # a job holds the rig
        rig_action(rig, lock, "stop", (1, 2))  # goes through at once
        assert all(str(rig.axes[leg].status().state) == "quick_stop_active" for leg in (1, 2))
        done = []
        worker = threading.Thread(target=lambda: done.append(_refusal(rig, lock)))
        worker.start()
        worker.join(30)
    assert done and isinstance(done[0], RigBusy) and "busy" in str(done[0])
    rig_action(rig, lock, "enable", (1, 2))  # from quick stop
    assert all(rig.axes[leg].status().enabled for leg in (1, 2))


def _refusal(rig, lock):
    try:
        rig_action(rig, lock, "enable", (1,))
    except Exception as exc:
        return exc
    return None


def test_job_refusals(session, tmp_path):
    """The session refuses a job while it has no rig or a move runs; the job's own refusals (a leg
    without a drive, a session file that exists) are its prepare's (station.services.sweep_job)."""
    out = tmp_path / "s.h5"
    assert session.job_refusal() == ("", "")
    with pytest.raises(InputError, match=r"no drive connected for leg\(s\) \[3\]"):
        prepare_sweep(SweepRequest(out=out, legs=(3,)), session.cfg, rig=session.rig)
    session.begin_move(1, MoveRequest(target_mm=2.0))
    assert session.job_refusal()[0] == "motion"
    assert str(session.move_refusal()).startswith("Leg 1 is still moving (to +2.000 mm at the default speed)")
    # the key to press is the front end's: the service names the action, the UI adds its key
    assert session.move_refusal().say({"stop": "x"}).endswith("wait for it, or stop it (x).")
    assert "(x)" not in str(session.move_refusal())
    session.end_move(1, "leg 1 at +2.0000 mm")
    assert session.move_refusal() is None
    out.write_bytes(b"")
    with pytest.raises(OutputExists):
        prepare_sweep(SweepRequest(out=out, legs=(1,)), session.cfg, rig=session.rig)
    assert out.read_bytes() == b""  # refused: nothing written
    assert prepare_sweep(SweepRequest(out=out, legs=(1,), force=True), session.cfg, rig=session.rig).out == out
    assert out.read_bytes() == b""  # prepared, not run: replaced only when the job runs
    assert RigSession(session.cfg, (1,)).job_refusal()[0] == "rig"  # not connected


def test_session_names_never_overwrite(tmp_path, monkeypatch):
    from station.services import sessions

    monkeypatch.setattr(sessions.time, "strftime", lambda fmt: "20260101-120000")
    cfg = StationConfig()
    cfg.recordings_dir = str(tmp_path)
    first = default_session_path(cfg, (1, 2))
    assert first == tmp_path / "ui-20260101-120000-leg1-2.h5"
    first.write_bytes(b"")
    assert default_session_path(cfg, (1, 2)) == tmp_path / "ui-20260101-120000-leg1-2-2.h5"
    assert default_session_path(cfg, prefix="run") == tmp_path / "run-20260101-120000.h5"
    source = tmp_path / "a.h5"
    assert replay_output_path(cfg, source) == tmp_path / "a.replay.h5"
    (tmp_path / "a.replay.h5").write_bytes(b"")
    assert replay_output_path(cfg, source) == tmp_path / "a.replay-2.h5"
    assert new_session_problem(first) == "exists"
    assert new_session_problem(tmp_path / "nowhere" / "x.h5") == "no folder"
    assert new_session_problem(Path(tmp_path / "new.h5")) == ""
