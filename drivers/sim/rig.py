"""The simulated rig: six leg plants behind a real Modbus server and a real serial pty.

One `VirtualClock` and one lock are shared by the drive server and the interferometer, so
both see the same physical leg at the same (virtual) time.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path

from drivers.clock import VirtualClock
from drivers.modbus.profile import DriveProfile
from drivers.sim.drive_server import SimDriveServer
from drivers.sim.interferometer_server import SimInterferometer
from drivers.sim.position_compare import TriggerLine
from drivers.plant.leg import LegPlant, PlantConfig, default_leg_configs


@dataclass
class SimRig:
    """Start with `start()`; then reach the drives at `drive_url` (Modbus TCP on 127.0.0.1)
    or `rtu_port` (Modbus RTU over a pty) and the interferometer at `laser_port` (a pty)."""

    time_scale: float = 0.0
    seed: int = 0
    legs: int = 6
    configs: list[PlantConfig] | None = None
    nv_path: Path | None = None
    profile: DriveProfile | None = None
    tcp_port: int = 0
    rtu: bool = False
    laser_offset_um: float = 0.0  # a bias on every laser reading (station.services.config [sim] laser_offset_um)
    # the simulated laser's protocol: "station" (docs/interferometer-protocol.md, the default) or
    # "linef1" (the µLine-F1's stream, drivers/sim/linef1_server.py; no trigger input: on-the-fly
    # passes are aligned on the rig's clock, the drive traced by the host)
    laser_protocol: str = "station"
    air_index: object = None  # linef1: the air's index (temp_c, pressure_pa, humidity_pct) -> n
    clock: VirtualClock = field(init=False)
    plants: dict[int, LegPlant] = field(init=False)
    drive_url: str = field(init=False, default="")
    rtu_port: str = field(init=False, default="")
    laser_port: str = field(init=False, default="")

    def __post_init__(self) -> None:
        self.clock = VirtualClock(self.time_scale)
        cfgs = self.configs or default_leg_configs(self.seed, self.legs)
        self.plants = {i + 1: LegPlant(cfg, seed=self.seed * 100 + i + 1) for i, cfg in enumerate(cfgs)}
        self.lock = threading.RLock()
        self.profile = self.profile or DriveProfile.load()
        self.drive_server = SimDriveServer(self.plants, self.clock, self.profile, nv_path=self.nv_path, lock=self.lock)
        self.trigger_line = TriggerLine()
        if self.laser_protocol == "linef1":
            from drivers.sim.linef1_server import SimLineF1

            # one beam, set up by the operator on the leg being prepared (enabled) when zeroed
            # on the plant's virtual time with the drives: the stream samples a move along its path
            # (the clock stops at every frame, drivers.clock.VirtualClock.add_events), and at
            # time scale 0 a move the host traces takes its time from the clock, so the host's
            # position polls see it under way (on-the-fly passes, docs/onthefly.md)
            self.laser_server = SimLineF1(self.plants, self.clock, lock=self.lock, aim=self._enabled_leg,
                                          index=self.air_index, seed=self.seed, offset_um=self.laser_offset_um,
                                          sync=self.drive_server.sync_leg)
            self.drive_server.set_traceable_moves(True)
        elif self.laser_protocol == "station":
            self.laser_server = SimInterferometer(self.plants, self.clock, lock=self.lock, seed=self.seed,
                                                offset_um=self.laser_offset_um)
            # the drives' position-compare outputs wired to the laser's trigger inputs (on-the-fly capture)
            self.trigger_line.connect(self.laser_server.trigger)
        else:
            raise ValueError(f"simulated laser protocol must be 'station' or 'linef1', got {self.laser_protocol!r}")
        self.drive_server.connect_trigger(self.trigger_line)
        self._started = False

    def _enabled_leg(self) -> int | None:
        """The leg the laser is set up on when zeroed: the enabled one (the last if it still is)."""
        from drivers.states import DriveState

        on = [leg for leg, m in self.drive_server._models.items() if m.state == DriveState.OPERATION_ENABLED]
        last = getattr(self.laser_server, "leg", None)
        return last if last in on else (on[0] if on else None)

    def start(self) -> "SimRig":
        port = self.drive_server.start_tcp("127.0.0.1", self.tcp_port)
        self.drive_url = f"tcp://127.0.0.1:{port}"
        if self.rtu:
            self.rtu_port = self.drive_server.start_rtu()
        self.laser_port = self.laser_server.start()
        self._started = True
        return self

    def stop(self) -> None:
        if self._started:
            self.laser_server.stop()
            self.drive_server.stop()
            self._started = False

    def __enter__(self) -> "SimRig":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
