"""The sample sessions of recordings/ (`station recordings`, recordings/README.md): the simulated
rig they are made on and how each is made (faults injected at fixed points). Their legs are the
plant's (procedures.synthetic.sample_plant_configs, beside the other sessions made from the plant);
this one needs the simulated devices (real Modbus TCP and pty), so it stays in the station layer.

Deterministic: fixed seeds on the virtual clock (`station recordings` regenerates them).

- calibration-6legs.h5: the seed paper's plan (361 targets at 0.5 mm over +/-90 mm, six
  bidirectional cycles, six legs: 25 992 points) on legs with every plant effect switched on,
  axial load changing between cycles and the room temperature swinging; one transient beam
  break (leg 3) and one drive fault (leg 5) on the way, both retried.
- verification-6legs.h5: after fitting the default model to the calibration, making a
  compensation table per leg and pushing it into the simulated drives (station.services.table_jobs.push_table:
  inactive bank, read back, switch, over the Modbus client), an ISO 230-2 test of all six legs on
  the same rig.
- fault-beam-break.h5: an ISO 230-2 test of legs 1-2, cut short by a beam break on leg 2 that
  does not clear (injected after point index FAULT_AFTER_INDEX): outcome "failed".
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from procedures.engine import events as ev
from procedures.acquisition.plans import iso230_plan, paper_plan
from procedures.engine.runner import CallbackSink
from procedures.synthetic import SAMPLE_JERK_MM_S3, SAMPLE_SEED, sample_plant_configs
from station.services.config import SimConfig, StationConfig

SAMPLES = ("calibration", "verification", "fault")
FILES = {"calibration": "calibration-6legs.h5", "verification": "verification-6legs.h5", "fault": "fault-beam-break.h5"}
CAL_BEAM_BREAK = (3, 1000)  # (leg, point of that leg after which its beam is interrupted once)
CAL_DRIVE_FAULT = (5, 2000)  # (leg, point of that leg after which its drive faults once)
FAULT_LEG = 2
FAULT_AFTER_INDEX = 157  # leg 2 run 5 (third upward pass), its 4th target is never measured


def open_sample_rig(seed: int = SAMPLE_SEED):
    """The simulated rig of the samples, opened by the composition root (`open_rig`: real Modbus
    TCP and pty) on the samples' legs, at time scale 0."""
    from dataclasses import replace

    from station.services.wiring import open_rig

    cfg = sample_config()
    return open_rig(replace(cfg, sim=replace(cfg.sim, seed=seed)), time_scale=0.0, leg_configs=sample_plant_configs(seed))


def _injector(actions: dict[int, Callable[[], None]], clear_beam: Callable[[ev.Fault], None] | None = None):
    """A sink calling actions[index] once point `index` is recorded (so the fault hits the next
    point), and `clear_beam` on a beam-break fault."""

    def on_event(e: ev.Event) -> None:
        if isinstance(e, ev.PointMeasured):
            action = actions.pop(int(e.record["index"]), None)
            if action:
                action()
        elif isinstance(e, ev.Fault) and clear_beam is not None and e.kind == "beam_break":
            clear_beam(e)

    return CallbackSink(on_event)


def make_calibration(rig, out: Path, cfg: StationConfig):
    from station.services.jobs import run_sweep

    plan = paper_plan((1, 2, 3, 4, 5, 6))
    beam_leg, beam_k = CAL_BEAM_BREAK
    drive_leg, drive_k = CAL_DRIVE_FAULT
    beam_after = plan.legs.index(beam_leg) * plan.points_per_leg + beam_k  # plan index
    drive_after = plan.legs.index(drive_leg) * plan.points_per_leg + drive_k
    sim = rig.sim
    sink = _injector(
        {beam_after: lambda: sim.laser_server.set_beam_break(beam_leg, True),
         drive_after: lambda: sim.drive_server.inject_fault(drive_leg, "overcurrent")},
        clear_beam=lambda f: sim.laser_server.set_beam_break(beam_leg, False),  # transient: one bad reading
    )
    return run_sweep(rig, plan, out, cfg, sinks=[sink], index=False)  # samples: no leg's record


def make_verification(rig, calibration: Path, out: Path, cfg: StationConfig) -> list[str]:
    """Fit, tabulate and load the tables into the drives, then an ISO 230-2 test. Returns lines
    describing what was loaded."""
    from procedures.fit import fit
    from station.services.table_jobs import push_table
    from procedures.io.recording.reader import read_session
    from procedures.compensation.table import make_table
    from station.services.jobs import run_sweep

    session = read_session(calibration)
    model = fit(session.points, "default", source={"path": str(calibration), "sha256": session.sha256})
    table = make_table(model, spec=rig.axes[min(rig.axes)].table_spec())
    lines = []
    for leg, leg_table in table.legs.items():
        # the station's safe push (inactive bank, read back, switch) over the Modbus client
        res = push_table(rig.axes[leg], leg_table, drive_url=rig.sim.drive_url,
                         source={"path": calibration.name, "sha256": session.sha256})
        lines.append(f"leg {leg}: table of {res.points} points, step {leg_table.step_mm:g} mm, pushed to bank "
                     f"{res.bank} (active), sha256 {res.table_sha256[:12]}")
    plan = iso230_plan((1, 2, 3, 4, 5, 6))
    # the sample is, by design, the sweep of the compensated legs (recorded with its tables, stage
    # "other"): confirmed here as `station sweep --yes` would (services.jobs.check_compensation)
    result = run_sweep(rig, plan, out, cfg, index=False, confirm_compensated=lambda question: True)
    return lines + [f"verification: {result.outcome}, {result.points} points"]


def make_fault(rig, out: Path, cfg: StationConfig):
    from station.services.jobs import run_sweep

    plan = iso230_plan((1, FAULT_LEG))
    sim = rig.sim
    sink = _injector({FAULT_AFTER_INDEX: lambda: sim.laser_server.set_beam_break(FAULT_LEG, True)})
    return run_sweep(rig, plan, out, cfg, sinks=[sink], index=False)  # samples: no leg's record


def sample_config() -> StationConfig:
    """The config recorded in each sample: it says how its rig moved (sim.jerk_mm_s3 = SAMPLE_JERK_MM_S3)."""
    return StationConfig(operator="station recordings", sim=SimConfig(jerk_mm_s3=SAMPLE_JERK_MM_S3))
