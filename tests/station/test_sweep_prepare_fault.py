"""A leg that cannot be prepared (enabled and zeroed at mid-stroke) stops the sweep with a fault
row saying so, like a point's fault: the session tells where and why it stopped."""

from __future__ import annotations

from procedures.acquisition.plans import iso230_plan
from procedures.io.recording.reader import read_session
from station.services.config import StationConfig
from station.services.jobs import run_sweep
from station.services.wiring import open_rig


def test_a_stalled_axis_while_preparing_its_leg_is_recorded_as_a_fault(tmp_path):
    out = tmp_path / "stall.h5"
    cfg = StationConfig()
    with open_rig(cfg, legs=(1, 2), time_scale=0.0) as rig:
        rig.sim.drive_server.set_stalled(2, True)  # leg 2 accepts moves but never arrives
        result = run_sweep(rig, iso230_plan((1, 2), -40.0, 40.0, step_mm=40.0, cycles=1), out, cfg)
    assert result.outcome == "failed"
    s = read_session(out)
    assert s.outcome == "failed" and set(int(v) for v in s.points["leg"]) == {1}  # leg 1 measured in full
    faults = s.faults
    assert len(faults) == 1 and int(faults["leg"][0]) == 2 and bool(faults["gave_up"][0])
    message = faults["message"][0].decode()
    assert message.startswith("preparing leg 2 (enable, zero at mid-stroke)") and "did not reach" in message
