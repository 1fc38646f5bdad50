"""The file size procedures.acquisition.plan_size estimates before a plan is built, against the files a
sweep on the simulated rig writes (station.services.jobs.run_sweep: the session writer, the real HDF5)."""

from __future__ import annotations

import pytest

from procedures.acquisition.plan_size import plan_size
from procedures.acquisition.plan_spec import PlanSpec, plan_from_spec
from station.services.config import StationConfig
from station.services.jobs import run_sweep
from station.services.wiring import open_rig


def test_the_file_size_is_the_writers(tmp_path):
    """Record two plans on the simulated rig; the estimate is within 15 % of each file."""
    cfg = StationConfig(operator="test")
    cfg.recordings_dir = str(tmp_path)
    for spec in (PlanSpec(step_mm=20.0, cycles=1, dwell_s=0.0, averaging_s=0.0),
                 PlanSpec(step_mm=1.0, cycles=2, dwell_s=0.0, averaging_s=0.0)):
        out = tmp_path / f"s{spec.step_mm}.h5"
        plan = plan_from_spec(spec)
        with open_rig(cfg, legs=plan.legs, time_scale=0.0) as rig:
            run_sweep(rig, plan, out, cfg)
        actual = out.stat().st_size
        assert plan_size(spec).file_bytes == pytest.approx(actual, rel=0.15), (spec, actual)
