"""The sample sessions of recordings/ (`station recordings`, recordings/README.md): the simulated
legs and rig they are made on, and how each is made (faults injected at fixed points).

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

from dataclasses import replace
from pathlib import Path
from typing import Callable

from procedures.engine import events as ev
from procedures.acquisition.plans import iso230_plan, paper_plan
from procedures.engine.runner import CallbackSink
from station.services.config import SimConfig, StationConfig

SAMPLES = ("calibration", "verification", "fault")
FILES = {"calibration": "calibration-6legs.h5", "verification": "verification-6legs.h5", "fault": "fault-beam-break.h5"}
SEED = 1
LOADS_N = (150.0, 150.0, 450.0, 450.0)  # axial load per pass: changes between bidirectional cycles
AMBIENT_SWING_K = 0.3
AMBIENT_PERIOD_S = 2.0 * 3600.0
CAL_BEAM_BREAK = (3, 1000)  # (leg, point of that leg after which its beam is interrupted once)
CAL_DRIVE_FAULT = (5, 2000)  # (leg, point of that leg after which its drive faults once)
FAULT_LEG = 2
FAULT_AFTER_INDEX = 157  # leg 2 run 5 (third upward pass), its 4th target is never measured
# the drives' jerk limit the samples were made with (0 = not limited): pinned, not the station's
# sim default (a real leg's, station.services.config.SimConfig.jerk_mm_s3), so recordings/*.h5 regenerate
# point for point; recorded in each sample's station_config as sim.jerk_mm_s3
JERK_MM_S3 = 0.0


def plant_configs(seed: int = SEED):
    """The six legs of the samples: the simulator's default legs with the load and the room
    temperature changing during the session, so that thermal, load and drift effects are all
    present and separable."""
    from drivers.sim.plant import PlantConfig, default_leg_configs

    base = replace(PlantConfig(), load_per_pass_n=LOADS_N, ambient_swing_k=AMBIENT_SWING_K,
                   ambient_period_s=AMBIENT_PERIOD_S, jerk_mm_s3=JERK_MM_S3)
    return default_leg_configs(seed, 6, base)


def open_sample_rig(seed: int = SEED):
    """The simulated rig of the samples, wired like `open_rig` does (real Modbus TCP and pty)."""
    from drivers.interferometer.client import SerialInterferometer
    from drivers.modbus.client import connect_axes
    from drivers.sim.rig import SimRig
    from station.services.wiring import Rig

    sim = SimRig(time_scale=0.0, seed=seed, configs=plant_configs(seed)).start()
    try:
        axes = connect_axes(sim.drive_url, (1, 2, 3, 4, 5, 6), sim.profile)
        laser = SerialInterferometer(sim.laser_port)
    except Exception:
        sim.stop()
        raise
    return Rig(axes, laser, sim.clock, "sim", f"simulated rig (seed {seed}) for the sample recordings", sim.profile,
               sim, [sim.stop])


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
    result = run_sweep(rig, plan, out, cfg, index=False)
    return lines + [f"verification: {result.outcome}, {result.points} points"]


def make_fault(rig, out: Path, cfg: StationConfig):
    from station.services.jobs import run_sweep

    plan = iso230_plan((1, FAULT_LEG))
    sim = rig.sim
    sink = _injector({FAULT_AFTER_INDEX: lambda: sim.laser_server.set_beam_break(FAULT_LEG, True)})
    return run_sweep(rig, plan, out, cfg, sinks=[sink], index=False)  # samples: no leg's record


def sample_config() -> StationConfig:
    """The config recorded in each sample: it says how its rig moved (sim.jerk_mm_s3 = JERK_MM_S3)."""
    return StationConfig(operator="station recordings", sim=SimConfig(jerk_mm_s3=JERK_MM_S3))
