"""Fixtures for the driver tests: simulated drives on real sockets and ptys (127.0.0.1 only)."""

from __future__ import annotations

import logging
import socket
import threading
from dataclasses import dataclass, field

import pytest

from drivers.clock import VirtualClock
from drivers.modbus.client import ModbusBus, ModbusServoAxis
from drivers.modbus.profile import DriveProfile
from drivers.sim.drive_server import SimDriveServer
from drivers.plant.leg import LegPlant, PlantConfig, default_leg_configs


@pytest.fixture(autouse=True, scope="session")
def _quiet_pymodbus():
    # frame dumps and "connection refused" errors are expected in these tests
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


@pytest.fixture(scope="session")
def profile() -> DriveProfile:
    return DriveProfile.load()


@dataclass
class SimDrives:
    """A running simulated drive server with its plants, clock and lock."""

    server: SimDriveServer
    plants: dict[int, LegPlant]
    clock: VirtualClock
    lock: threading.RLock
    profile: DriveProfile
    url: str = ""
    buses: list[ModbusBus] = field(default_factory=list)

    def bus(self, timeout_s: float = 1.0, retries: int = 1, url: str | None = None) -> ModbusBus:
        b = ModbusBus.from_url(url or self.url, timeout_s=timeout_s, retries=retries)
        self.buses.append(b)
        return b

    def axis(self, leg: int, bus: ModbusBus | None = None, **kw) -> ModbusServoAxis:
        return ModbusServoAxis(bus or self.bus(), leg, self.profile, **kw)


@pytest.fixture
def sim_drives(profile):
    """Factory: `sim_drives(time_scale=0, configs=None, rtu=False, nv_path=None)` starts a
    simulated drive server for six legs and returns a SimDrives; everything stops at teardown."""
    started: list[SimDrives] = []

    def make(time_scale: float = 0.0, configs: list[PlantConfig] | None = None, rtu: bool = False,
             nv_path=None, legs: int = 6, seed: int = 0) -> SimDrives:
        clock = VirtualClock(time_scale)
        cfgs = configs or default_leg_configs(seed, legs)
        plants = {i + 1: LegPlant(c, seed=seed * 100 + i + 1) for i, c in enumerate(cfgs)}
        lock = threading.RLock()
        server = SimDriveServer(plants, clock, profile, nv_path=nv_path, lock=lock)
        sd = SimDrives(server, plants, clock, lock, profile)
        started.append(sd)
        if rtu:
            sd.url = f"rtu://{server.start_rtu()}?baud=115200"
        else:
            sd.url = f"tcp://127.0.0.1:{server.start_tcp('127.0.0.1', 0)}"
        return sd

    yield make
    for sd in started:
        for b in sd.buses:
            b.close()
        sd.server.stop()


@pytest.fixture
def closed_port() -> int:
    """A TCP port on 127.0.0.1 with nothing listening (bound, then released)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


