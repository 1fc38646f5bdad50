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
    # known transport delays (bench/bench_latency.py), on the rig's clock: the µLine-F1's frames
    # leave `laser_latency_s` (+ uniform 0..`laser_jitter_s`) after their instant (time scale 0);
    # a Modbus request reaches the drive `drive_delay_s[0]` after it is sent, its reply the host
    # `drive_delay_s[1]` after the drive read it, each plus half a uniform 0..`drive_jitter_s`
    laser_latency_s: float = 0.0
    laser_jitter_s: float = 0.0
    drive_delay_s: tuple[float, float] = (0.0, 0.0)
    drive_jitter_s: float = 0.0
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
        if min(*self.drive_delay_s, self.drive_jitter_s, self.laser_latency_s, self.laser_jitter_s) < 0:
            raise ValueError("the simulated transports' delays and jitters must be >= 0 s")
        self.drive_server.request_delay_s, self.drive_server.response_delay_s = map(float, self.drive_delay_s)
        self.drive_server.delay_jitter_s = float(self.drive_jitter_s)
        if (self.laser_latency_s or self.laser_jitter_s) and (self.laser_protocol != "linef1" or self.time_scale != 0):
            raise ValueError("a simulated laser latency needs the µLine-F1 (laser_protocol 'linef1') at time scale 0: "
                             "the station's own laser latches at the drive's compare pulse, and at time scale > 0 "
                             "the frames are written by the serving thread as they fall due")
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
                                          sync=self.drive_server.sync_leg, latency_s=self.laser_latency_s,
                                          jitter_s=self.laser_jitter_s)
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
